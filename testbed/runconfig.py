"""What a run is asked to do: `RunConfig`, and the `testbed run` options that make one.

`RunConfig` is the whole description of a run; `config.json` is its `to_dict()` plus what
the run derived from it (start positions, timer phases), so a run can be repeated from its
directory. The command line's checks live here; the run itself is testbed.run.
"""

from __future__ import annotations

import argparse
import re
from dataclasses import asdict, dataclass

from node import coordination
from node.flood import MODES as FLOOD_MODES
from node.timing import STEP_S
from testbed.errors import UsageError
from testbed.world.worldmap import START_PLACEMENTS
from topology.argtypes import number
from topology.spec import AODV_PROFILES, LOS_MODELS, RANGE_MODELS

ROUTINGS = ("babel", "batman", "aodv", "oracle", "none")


@dataclass(frozen=True)
class RunConfig:
    robots: int
    comm_range: float
    laser_range: float = 2.0
    seed: int = 1
    time_scale: float = 1.0
    routing: str = "babel"
    aodv_profile: str = "rfc"  # aodv.params.PROFILES: rfc or ns3 (routing aodv only)
    map: str | None = None
    loss_pct: float = 0.0
    delay_ms: float = 0.0
    range_model: str = "disc"  # topology.ranges: disc (the paper's), lossy, los, los-lossy
    wall_loss_pct: float | None = None  # los: a wall costs this much loss (None: blocks)
    capture: bool = False
    max_steps: int = 3000
    coordination: str = coordination.DEFAULT  # node.coordination: "paper" or "ours"
    start: str = "corner"  # start placement: "corner", "centre" or "spread" (worldmap)
    # Beyond the contract's config keys (recorded too, so a run is reproducible):
    map_cell: float = 0.05
    laser_rays: int = 360
    speed: float = 0.1  # m per step (1 m/s)
    radius: float = 0.15
    plan_period: int = 20
    map_period: int = 10
    flood: str = "pruned"  # node.flood: "pruned" (self-pruning) or "blind"
    display_pos: tuple[float, float] | None = None  # default: the map's centre
    snapshots: tuple[int, ...] = ()
    kill: tuple[tuple[int, int], ...] = ()  # (robot, step): fault injection, SIGKILL
    view: str | None = None  # --view [HOST:]PORT: the live page (testbed.view.live)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["display_pos"] = list(self.display_pos) if self.display_pos else None
        d["snapshots"] = list(self.snapshots)
        d["kill"] = [f"{k}:{s}" for k, s in self.kill]
        return d


def _kill(text: str) -> tuple[int, int]:
    m = re.fullmatch(r"r?(\d+):(\d+)", text)
    if not m:
        raise argparse.ArgumentTypeError(f"--kill {text!r} is not ROBOT:STEP (e.g. r2:150)")
    return int(m[1]), int(m[2])


def _point(text: str) -> tuple[float, float]:
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not X,Y in metres") from None
    return x, y


def _steps(text: str) -> tuple[int, ...]:
    try:
        return tuple(sorted({int(s) for s in text.split(",") if s.strip()}))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a list of steps") from None


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The `testbed run` options."""
    a = parser.add_argument
    a("--robots", type=number(int, "robots", minimum=1), required=True, help="team size")
    a("--comm-range", type=number(float, "comm range", above=0), required=True, help="metres")
    a("--laser-range", type=number(float, "laser range", above=0), default=2.0, help="metres")
    a("--seed", type=number(int, "seed", minimum=0), default=1)
    a("--out", required=True, help="run directory to write")
    a("--time-scale", type=number(float, "time scale", above=0), default=1.0)
    a("--routing", choices=ROUTINGS, default="babel")
    a("--aodv-profile", choices=AODV_PROFILES, default="rfc",
      help="AODV parameters: rfc (RFC 3561 section 10, default) or ns3 (ns-3's "
           "defaults)")  # fmt: skip
    a("--map", help="PNG map (dark pixels are obstacles); default: empty 20 x 20 m")
    a("--map-cell", type=number(float, "map cell", above=0), default=0.05, help="m per pixel")
    a("--loss", type=number(float, "loss", minimum=0), default=0.0, help="percent, every link")
    a("--delay", type=number(float, "delay", minimum=0), default=0.0, help="ms, every link")
    a("--range-model", choices=RANGE_MODELS, default="disc",
      help="radio: disc (default, the paper's), lossy, los (the map's walls block the "
           "radio), los-lossy")  # fmt: skip
    a("--wall-loss", type=number(float, "wall loss", minimum=0), metavar="PCT",
      help="with los: each wall crossed costs PCT loss instead of blocking")  # fmt: skip
    a("--capture", action="store_true", help="write pcaps/rK.pcap")
    a("--max-steps", type=number(int, "max steps", minimum=1), default=3000)
    a("--laser-rays", type=number(int, "laser rays", minimum=4), default=360)
    a("--speed", type=number(float, "speed", above=0), default=1.0, help="m/s")
    a("--map-period", type=number(int, "map period", minimum=1), default=10,
      help="steps between a robot's map floods (default 10)")  # fmt: skip
    a(
        "--flood",
        choices=FLOOD_MODES,
        default="pruned",
        help="map flooding: self-pruning (default) or blind (every robot relays every flood)",
    )
    a("--coordination", choices=coordination.MODES, default=coordination.DEFAULT,
      help="goal coordination: 'paper' reads the paper's rules literally, 'ours' (default) "
           "departs from them where the text is silent; see README, 'Coordination'")  # fmt: skip
    a("--start", choices=START_PLACEMENTS, default="corner",
      help="start placement: clustered near a corner (default, as in the paper), clustered "
           "at the centre, or spread over the map")  # fmt: skip
    a("--display-pos", type=_point, help="X,Y of the display (default: map centre)")
    a("--snapshots", type=_steps, default=(),
      help="display snapshot steps, e.g. 200,600 (default 100,250,500,1000,2000; always one "
           "at the end)")  # fmt: skip
    a("--kill", type=_kill, action="append", default=[], help="ROBOT:STEP, SIGKILL (testing)")
    a("--name", help="testbed name (default: random 'run' + 4 hex digits)")
    a("--view", metavar="[HOST:]PORT",
      help="serve a live view of the run (127.0.0.1 unless a host is given)")  # fmt: skip
    a("--quiet", action="store_true", help="no progress line")


def _view(text: str | None) -> str | None:
    if text is None:
        return None
    from testbed.view.server import parse_bind

    try:
        parse_bind(text)
    except ValueError as e:
        raise UsageError(str(e)) from None
    return text


def config_from_args(args: argparse.Namespace) -> RunConfig:
    if args.loss > 100:
        raise UsageError(f"loss {args.loss}% is more than 100%")
    if args.wall_loss is not None and args.range_model not in LOS_MODELS:
        raise UsageError("--wall-loss is for the los range models: add --range-model los")
    if args.wall_loss is not None and args.wall_loss > 100:
        raise UsageError(f"wall loss {args.wall_loss}% is more than 100%")
    if args.robots > 50:
        raise UsageError(f"at most 50 robots ({args.robots} asked)")
    for k, _ in args.kill:
        if not 1 <= k <= args.robots:
            raise UsageError(f"--kill names robot {k}, but the team is r1..r{args.robots}")
    return RunConfig(
        robots=args.robots, comm_range=args.comm_range, laser_range=args.laser_range,
        seed=args.seed, time_scale=args.time_scale, routing=args.routing,
        aodv_profile=args.aodv_profile, map=args.map,
        loss_pct=args.loss, delay_ms=args.delay, capture=args.capture,
        range_model=args.range_model, wall_loss_pct=args.wall_loss,
        max_steps=args.max_steps, map_cell=args.map_cell, laser_rays=args.laser_rays,
        speed=args.speed * STEP_S, display_pos=args.display_pos, snapshots=args.snapshots,
        map_period=args.map_period, flood=args.flood, coordination=args.coordination,
        start=args.start, kill=tuple(args.kill), view=_view(args.view),
    )  # fmt: skip
