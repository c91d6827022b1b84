"""A run's first stage: what it will do, checked, and its directory with config.json.

Theory of operation. `prepare(cfg, out, name)` builds the world (ground truth, seeded start
positions, lasers), each robot's timer phase (seeded, as robots booted one by one would
start theirs), the display's position and the description of the testbed network (one
namespace per robot plus one for the display, robot N+1, which does not explore). Then it
checks everything that can be checked before anything exists: the middleware's Python
package (node.messaging), the network's description, root and tools
(topology.network.preflight), a testbed name nobody uses, the kernel features the
impairments need, the live view's address, and the output directory (testbed.run.files: a
directory holding a run is refused unless `replace`). Each is a
UsageError (one line, exit 2) that leaves nothing behind. Only then it makes the directory
and writes config.json, the first file of the run-results contract (docs/run-results.md),
and returns a frozen `PreparedRun`, which the next stage (testbed.run.execute.Run) takes.
"""

from __future__ import annotations

import math
import os
import shutil
from dataclasses import dataclass

import numpy as np

from common.errors import UsageError
from node.displaysteps import VIDEO_EVERY, DisplaySteps
from node.rays import Laser
from testbed.files import configfile, layout
from testbed.files.failures import battery_kill
from testbed.files.runconfig import RunConfig
from testbed.run.arguments import network_fields
from testbed.run.files import claim_directory, make_directory
from testbed.world.world import World
from testbed.world.worldmap import (
    GroundTruth,
    empty_terrain,
    free_space,
    load_png,
    start_positions,
)
from topology.spec import NetworkSpec

DEFAULT_SNAPSHOTS = (100, 250, 500, 1000, 2000)  # display PNGs (plus one at the end)


@dataclass(frozen=True)
class PreparedRun:
    """A run checked and described, its directory made and config.json written."""

    cfg: RunConfig
    out: str  # absolute
    name: str  # the testbed's name
    truth: GroundTruth
    world: World
    phases: tuple[int, ...]  # each robot's timer phase (steps)
    display_pos: tuple[float, float]
    spec: NetworkSpec
    config: dict  # config.json's contents

    @property
    def robots(self) -> int:
        return self.cfg.robots

    @property
    def display_k(self) -> int:
        return self.cfg.robots + 1

    @property
    def snapshots(self) -> tuple[int, ...]:
        """The steps at which the display saves its map (plus one at the end)."""
        return tuple(self.config["snapshots"])

    @property
    def display_steps(self) -> DisplaySteps:
        """The steps the display acts on (its frames; node.displaysteps)."""
        return DisplaySteps(self.cfg.map_period, VIDEO_EVERY, frozenset(self.snapshots))

    def path(self, *parts: str) -> str:
        return os.path.join(self.out, *parts)


def prepare(cfg: RunConfig, out: str, name: str, replace: bool = False) -> PreparedRun:
    """The world, the network's description, the checks, the directory and config.json;
    UsageError for a run this machine cannot do or a directory it may not write (nothing
    is created then)."""
    out = os.path.abspath(out)
    check_middleware(cfg.middleware)
    check_maps(cfg.maps, cfg.middleware)
    truth = ground_truth(cfg)
    check_laser(cfg.laser_range, truth.size_m)
    starts, phases = seeded_placement(cfg, truth)
    world = make_world(cfg, truth, starts)
    w_m, h_m = truth.size_m
    x, y = cfg.display_pos or (w_m / 2, h_m / 2)
    display_pos = (x, y)
    spec = _network_spec(cfg, name, tuple(starts) + (display_pos,), out)
    check_machine(spec)
    if cfg.view:
        check_view(cfg.view)
    claim_directory(out, replace)
    make_directory(out, cfg.capture, replace)
    config = cfg.to_dict()
    config.update(map_size=list(truth.shape), starts=[list(p) for p in starts],
                  timer_phases=list(phases), display=cfg.robots + 1,
                  display_pos=list(display_pos), name=name,
                  snapshots=sorted(cfg.snapshots or DEFAULT_SNAPSHOTS))  # fmt: skip
    planned = battery_kill(cfg.battery_failure, cfg.robots, cfg.laser_range)
    if planned:  # the step the battery failure was fixed at (testbed.files.failures)
        config["battery_kill"] = f"r{planned[0]}:{planned[1]}"
    prepared = PreparedRun(cfg, out, name, truth, world, phases, display_pos, spec, config)
    try:
        configfile.write(prepared.out, prepared.config)
        if cfg.map:  # the replay shows the run's own copy (testbed.view.served)
            shutil.copyfile(cfg.map, prepared.path("map.png"))
    except OSError as e:
        raise UsageError(f"--out {out}: cannot write there: {e.strerror}") from None
    return prepared


def ground_truth(cfg: RunConfig) -> GroundTruth:
    """The run's map: --map's PNG, or the paper's empty terrain."""
    return load_png(cfg.map, cfg.map_cell) if cfg.map else empty_terrain()


def seeded_placement(
    cfg: RunConfig, truth: GroundTruth
) -> tuple[list[tuple[float, float]], tuple[int, ...]]:
    """The robots' start positions and timer phases, both drawn from one generator seeded
    with `cfg.seed` (in that order): what makes a lone robot's run repeatable."""
    rng = np.random.default_rng(cfg.seed)
    starts = start_positions(truth, cfg.robots, rng, cfg.radius, cfg.start)
    phases = tuple(int(v) for v in rng.integers(0, cfg.plan_period, size=cfg.robots))
    return starts, phases


def make_world(cfg: RunConfig, truth: GroundTruth, starts: list[tuple[float, float]]) -> World:
    """The world of a run of `cfg` on `truth`, its robots at `starts` (also the in-process
    twin's, testbed.run.twin)."""
    laser = Laser(cfg.laser_range, cfg.laser_rays, truth.cell)
    return World(truth, starts, laser, free_space(truth, starts), cfg.speed, cfg.radius)


def check_middleware(name: str) -> None:
    """UsageError naming the Python package to install when middleware `name` cannot be
    opened here (its module is imported, as the robots will)."""
    from node.messaging import unavailable

    why = unavailable(name)
    if why:
        raise UsageError(why)


def check_maps(maps: str, middleware: str) -> None:
    """UsageError for maps over publish/subscribe on a middleware without them."""
    from node.messaging.maps import refusal

    why = refusal(maps, middleware)
    if why:
        raise UsageError(why)


def check_laser(laser_range: float, size_m: tuple[float, float]) -> None:
    """UsageError for a laser longer than the map's diagonal: it could see nothing more (the
    map is walled), and its geometry would only cost memory and time."""
    diagonal = math.hypot(*size_m)
    if laser_range > diagonal:
        raise UsageError(
            f"--laser-range {laser_range:g} is longer than the map's diagonal ({diagonal:.1f} m "
            f"on {size_m[0]:g} x {size_m[1]:g} m): a laser sees no farther than the map"
        )


def _network_spec(cfg: RunConfig, name: str, positions: tuple, out: str) -> NetworkSpec:
    try:
        return NetworkSpec(
            name=name,
            positions=positions,
            map_png=os.path.abspath(cfg.map) if cfg.map else None,
            capture_dir=layout.pcaps_dir(out) if cfg.capture else None,
            # The daemons' statistics are read as they stop; only the live view reads them
            # while the run goes on (an idle daemon that rewrites its file every second pays
            # for it in wake-ups and disk writes).
            aodv_stats_period=1.0 if cfg.view else 0.0,
            **network_fields(cfg),
        )
    except ValueError as e:
        raise UsageError(str(e)) from None


def check_machine(spec: NetworkSpec) -> None:
    """Root, the tools, a free testbed name and the kernel features the impairments need;
    UsageError if not."""
    from topology import state
    from topology.kernel.impair import kernel_has_netem, missing_feature
    from topology.network import preflight

    preflight(spec)
    if os.path.exists(state.state_path(spec.name)):
        raise UsageError(f"testbed name {spec.name!r} is already in use (--name)")
    imp = spec.impairment
    if imp.is_none:
        return
    missing = missing_feature(imp, kernel_has_netem(), shutil.which("nft") is not None)
    if missing:
        raise UsageError(missing)


def check_view(bind: str) -> None:
    """UsageError unless the live view can listen at `bind` ([HOST:]PORT) now."""
    from testbed.view.server import check_bind

    try:
        check_bind(bind)
    except ValueError as e:
        raise UsageError(str(e)) from None
