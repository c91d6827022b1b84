"""What a run is asked to do: `RunConfig`, the option table.

`RunConfig` is the whole description of a run; `config.json` is its `to_dict()` plus what
the run derived from it (start positions, timer phases), so a run can be repeated from its
directory. Each run option is declared once, on its field (`option(...)`, testbed.files.options):
`testbed run`'s flags, the `net up` flags it shares, a sweep file's keys and the argv a sweep
hands a run are all made from these declarations. The run itself is testbed.run.execute.

This module is data: it checks options against each other (`refusal`) but asks nothing of
this machine. What only this machine can answer (is the C++ robot built and does it carry
the middleware, is the compiled AODV daemon built, can the live view listen there) is
testbed.run.arguments's, which `testbed run` and a sweep call.
"""

from __future__ import annotations

import argparse
import re
from collections.abc import Set
from dataclasses import asdict, dataclass
from pathlib import Path

from common.argtypes import checked
from node.argsdecl import MAX_LASER_CELLS, maps_refusal
from node.argsdecl import MAX_RANGE_M as MAX_LASER_RANGE_M
from node.argsdecl import bounds as robot
from node.timing import STEP_S
from testbed.files import failures, resultconfig
from testbed.files import options as runoptions
from testbed.files.isolation import Outage
from testbed.files.options import CHANGED, GRID, NONZERO, RUN, VARIED, GridDim, option
from topology.spec import (
    AODV_DAEMONS,
    AODV_PROFILES,
    CELL_M,
    LOS_MODELS,
    MAX_COORD_M,
    MEDIA,
    RANGE_MODELS,
    ROUTINGS,
    VETH,
    WIFI_LOSSES,
    WIFI_STANDARDS,
    check_position,
)

# Bounds of the options that have no natural one (docs/guide.md's option list and `--help`):
MAX_STEPS = 10_000_000  # 11 days of emulated time at a step of 0.1 s
# The largest team `testbed run` takes: the largest that ran faithful at K = 1 in 3 runs of 3
# (seeds 5, 6, 7) on the 2-core development machine, with the C++ robot and the compiled AODV
# daemon: 80 (90 was faithful in 2 of 3, 100 in 3 of 6: docs/measurements.md, "The compiled
# AODV daemon's benchmarks"). Those verdicts predate the check of the host's ARP table
# (topology.kernel.neightable): at 100 robots it was full and dropped about four sends in
# five; on a host with the default limit a team past about 30 is now judged not faithful
# when it overflows.
MAX_TEAM = 80
MAX_LASER_RAYS = 10_000  # a ray every 0.036 degrees; the paper's robots have 360
MAX_SNAPSHOTS = 100
# Where the team starts (testbed.world.worldmap places them): near a corner, as in the paper.
START_PLACEMENTS = ("corner", "centre", "spread")
# --robot (testbed.run.robotchoice) and --aodv-daemon (testbed.run.daemonchoice).
ROBOT_CHOICES = ("auto", "cpp", "python")
AODV_DAEMON_CHOICES = ("auto", *reversed(AODV_DAEMONS))  # auto, cpp, python


def _kill(text: str) -> tuple[int, int]:
    m = re.fullmatch(r"r?([0-9]{1,4}):([0-9]{1,8})", text)
    if not m or int(m[2]) > MAX_STEPS:
        raise argparse.ArgumentTypeError(
            f"--kill {text[:40]!r} is not ROBOT:STEP (e.g. r2:150; a step up to {MAX_STEPS:,})"
        )
    return int(m[1]), int(m[2])


def _outage(text: str) -> Outage:
    """An --isolate window (testbed.files.isolation), its steps within MAX_STEPS like every
    step of the options; ValueError saying what is wrong."""
    o = Outage.parse(text)
    if o.start > MAX_STEPS or o.steps > MAX_STEPS:
        raise ValueError(f"--isolate {text[:40]!r}: STEP and STEPS are at most {MAX_STEPS:,}")
    return o


_isolate = checked(_outage)


def _point(text: str) -> tuple[float, float]:
    try:
        return check_position(text.split(","), f"--display-pos {text[:40]!r}")
    except ValueError as e:
        raise argparse.ArgumentTypeError(f"{e} (X,Y in metres)") from None


def _steps(text: str) -> tuple[int, ...]:
    words = [s.strip() for s in text.split(",") if s.strip()]
    if len(words) > MAX_SNAPSHOTS or not all(
        w.isascii() and w.isdigit() and len(w) <= 8 and int(w) <= MAX_STEPS for w in words
    ):
        raise argparse.ArgumentTypeError(
            f"--snapshots {text[:40]!r} is not a list of steps (at most {MAX_SNAPSHOTS}, each "
            f"0..{MAX_STEPS:,})"
        )
    return tuple(sorted({int(w) for w in words}))


EMPTY_MAP = "empty"  # how run ids and sweep files name the paper's empty terrain


def fmt(x: float) -> str:
    """A number as it appears in run ids: 10.0 -> '10', 1.5 -> '1.5'."""
    return f"{x:g}"


def map_label(m: str | None) -> str:
    """The name a map has in run ids: `empty`, or the file's stem (letters and digits)."""
    return EMPTY_MAP if m is None else "".join(ch for ch in Path(m).stem if ch.isalnum())


def medium_label(medium: str) -> str:
    """The name a medium has in run ids: its letters and digits (`veth`, `ns3wifi`)."""
    return "".join(ch for ch in medium if ch.isalnum())


STEP_S_TEXT = f"{STEP_S:g} s"
SEED_HELP = (
    "random seed of the start positions and the robots' timer phases; it makes a lone "
    "robot's run repeatable, not a team's: real timing decides which robot hears what first "
    "(one seed gave a team 823 steps, then 920)"
)


@dataclass(frozen=True)
class RunConfig:
    """One run's description. Fields made with `option(...)` are the run options (see
    testbed.files.options): `testbed run`'s flags, a sweep file's keys, `net up`'s network flags."""

    robots: int = option(int, "team size (exploring robots)", minimum=1, maximum=MAX_TEAM,
                         metavar="N", sweep={GRID}, in_result=True,
                         grid=GridDim(0, lambda n: f"n{n:02d}", seeded=True))  # fmt: skip
    comm_range: float = option(float, "radio range", unit="metres", above=0, metavar="M",
                               maximum=MAX_COORD_M,
                               sweep={GRID}, net=True, in_result=True,
                               grid=GridDim(1, lambda r: f"c{fmt(r)}", seeded=True))  # fmt: skip
    laser_range: float = option(float, "laser range, at least a map cell and at most "
                                f"{MAX_LASER_RANGE_M:g} m and the map's diagonal",
                                **robot("laser_range"), unit="metres",
                                maximum=MAX_LASER_RANGE_M, metavar="M", sweep={GRID},
                                in_result=True,
                                grid=GridDim(2, lambda r: f"l{fmt(r)}", seeded=True))  # fmt: skip
    seed: int = option(int, SEED_HELP, 1, minimum=0, maximum=2**63 - 1, metavar="S", in_result=True)
    time_scale: float = option(
        float, f"speed-up of robot time over wall time: a step of {STEP_S_TEXT} lasts "
        f"{STEP_S_TEXT} / K", **robot("time_scale"), unit="factor",
        metavar="K", sweep={RUN}, net=True, in_result=True,
    )  # fmt: skip
    routing: str = option(str, "routing protocol", "aodv", choices=ROUTINGS,
                          sweep={GRID, RUN}, net=True, in_result=True,
                          grid=GridDim(7, str, VARIED))  # fmt: skip
    aodv_profile: str = option(
        str, "AODV parameters (routing aodv): rfc, RFC 3561 section 10, or ns3, ns-3's "
        "defaults", "rfc", choices=AODV_PROFILES, sweep={RUN}, newer=True, net=True,
    )  # fmt: skip
    aodv_daemon: str = option(
        str, "the AODV daemon (routing aodv): auto (the compiled daemon, build/tb-aodv, where "
        "make setup built it, else the Python daemon), cpp, or python (the reference); "
        "testbed.run.daemonchoice", "auto", choices=AODV_DAEMON_CHOICES, sweep={GRID, RUN},
        newer=True, net=True, grid=GridDim(14, lambda d: f"aodv{d}", VARIED),
    )  # fmt: skip
    map: str | None = option(
        str, "PNG map: dark pixels are obstacles, and walls for the los range models", None,
        metavar="PNG", default_text="an empty 20 x 20 m terrain", sweep={GRID, RUN},
        in_result=True,
        grid=GridDim(8, lambda m: f"m{map_label(m)}", VARIED),
    )  # fmt: skip
    loss_pct: float = option(float, "packet loss on every link", 0.0, unit="percent",
                             minimum=0, maximum=100, metavar="PCT", cli="--loss",
                             sweep={GRID}, net=True, in_result=True,
                             grid=GridDim(3, lambda p: f"p{fmt(p)}", NONZERO,
                                          seeded=True))  # fmt: skip
    delay_ms: float = option(float, "delay on every link, with sch_netem", 0.0, unit="ms",
                             minimum=0, maximum=60_000, metavar="MS", cli="--delay",
                             sweep={GRID}, net=True, in_result=True,
                             grid=GridDim(4, lambda d: f"d{fmt(d)}", NONZERO,
                                          seeded=True))  # fmt: skip
    range_model: str = option(
        str, "radio: disc (the paper's), lossy, los (the map's walls block the radio), "
        "los-lossy", "disc", choices=RANGE_MODELS, sweep={RUN}, newer=True, net=True,
    )  # fmt: skip
    wall_loss_pct: float | None = option(
        float, "with los: each wall crossed costs PCT loss instead of blocking", None,
        unit="percent", minimum=0, maximum=100, metavar="PCT", cli="--wall-loss",
        default_text="walls block", sweep={RUN}, newer=True, net=True,
    )  # fmt: skip
    medium: str = option(
        str, "radio medium: veth, perfect links switched by range, or ns3-wifi, ns-3's "
        "802.11 ad hoc channel (docs/ns3-medium.md)", VETH, choices=MEDIA,
        sweep={GRID, RUN}, newer=True, net=True, grid=GridDim(9, medium_label, VARIED),
    )  # fmt: skip
    wifi_loss: str = option(
        str, "ns3-wifi propagation: range, a cut-off at the radio range, or logdistance",
        "range", choices=WIFI_LOSSES, sweep={RUN}, newer=True, net=True,
    )  # fmt: skip
    wifi_standard: str = option(str, "ns3-wifi 802.11 standard", "80211a", choices=WIFI_STANDARDS,
                                sweep={RUN}, newer=True, net=True)  # fmt: skip
    wifi_rate: str = option(
        str, "ns3-wifi data rate: an ns-3 WifiMode (e.g. OfdmRate12Mbps) or minstrel", "",
        metavar="MODE", default_text="the standard's fastest", sweep={RUN}, newer=True,
        net=True,
    )  # fmt: skip
    capture: bool = option(bool, "write pcaps/rK.pcap, one capture per robot", False,
                           sweep={RUN}, in_result=True)  # fmt: skip
    max_steps: int = option(int, "stop the run after this many steps", 3000, metavar="N",
                            unit=f"steps of {STEP_S_TEXT}", minimum=1, maximum=MAX_STEPS,
                            sweep={RUN}, in_result=True)  # fmt: skip
    coordination: str = option(
        str, "goal coordination: 'paper' reads the paper's rules literally, 'ours' departs "
        "from them where the text is silent; see docs/guide.md, 'Coordination'",
        **robot("coordination"), sweep={GRID}, in_result=True,
        grid=GridDim(5, str, CHANGED),
    )  # fmt: skip
    start: str = option(str, "start placement: clustered near a corner (as in the paper), "
                        "clustered at the centre, or spread over the map", "corner",
                        choices=START_PLACEMENTS, sweep={GRID}, in_result=True,
                        grid=GridDim(6, str, CHANGED))  # fmt: skip
    middleware: str = option(
        str, "the middleware of the robots' goal messages (goals, requests to plan again): "
        "see docs/middleware.md", **robot("middleware"),
        sweep={GRID, RUN}, newer=True, grid=GridDim(10, medium_label, VARIED),
    )  # fmt: skip
    maps: str = option(
        str, "how robots share their maps: flood, UDP broadcast relayed with self-pruning (the "
        "paper's), or pubsub, published on the middleware's topics (zenoh or dds only; see "
        "docs/middleware.md)", **robot("maps"), sweep={GRID, RUN}, newer=True,
        grid=GridDim(12, str, VARIED),
    )  # fmt: skip
    battery_failure: str = option(
        str, "one robot's battery fails: none, or midrun, robot rN killed at the team's "
        "mid-run step (testbed.files.failures: half of a typical finishing step for the team size "
        "and laser; docs/middleware.md)", "none", choices=failures.BATTERY_FAILURES,
        sweep={GRID, RUN}, newer=True, grid=GridDim(11, str, CHANGED),
    )  # fmt: skip
    # Beyond the contract's config keys (recorded too, so a run is reproducible; result.json
    # keeps them under config's `extra`):
    map_cell: float = option(float, "size of a pixel of --map", CELL_M, unit="metres",
                             minimum=0.001, maximum=100, metavar="M", net=True)  # fmt: skip
    laser_rays: int = option(int, "rays of a laser scan", **robot("laser_rays"), metavar="N",
                             maximum=MAX_LASER_RAYS)  # fmt: skip
    # The field is in metres per step, the flag in m/s (per_step).
    speed: float = option(float, "robot speed", **robot("speed"), unit="m/s", metavar="V",
                          maximum=100,
                          per_step=STEP_S)  # fmt: skip
    radius: float = robot("radius")["default"]
    plan_period: int = robot("plan_period")["default"]
    map_period: int = option(int, "steps between a robot's map floods", **robot("map_period"),
                             unit="steps", metavar="N", maximum=MAX_STEPS)  # fmt: skip
    flood: str = option(str, "map flooding: pruned (self-pruning) or blind (every robot "
                        "relays every flood)", **robot("flood"))  # fmt: skip
    display_pos: tuple[float, float] | None = option(
        str, "where the display stands", None, unit="metres", parse=_point, metavar="X,Y",
        text=lambda p: f"{p[0]!r},{p[1]!r}", default_text="the map's centre",
    )  # fmt: skip
    snapshots: tuple[int, ...] = option(
        str, "display snapshot steps, e.g. 200,600; one is always taken at the end", (),
        unit="steps", parse=_steps, text=lambda s: ",".join(map(str, s)), metavar="STEPS",
        default_text="100,250,500,1000,2000",
    )  # fmt: skip
    kill: tuple[tuple[int, int], ...] = option(
        str, "SIGKILL robot ROBOT at step STEP (fault injection, for tests; repeatable)", (),
        metavar="ROBOT:STEP", parse=_kill, text=lambda k: f"r{k[0]}:{k[1]}", repeat=True,
        default_text="none",
    )  # fmt: skip
    isolate: tuple[Outage, ...] = option(
        str, "take robot ROBOT out of everyone's radio range from step STEP for STEPS steps, "
        "then back (a partition: every link of it off, whatever the positions; the robot "
        "goes on exploring; veth medium; repeatable)", (), metavar="ROBOT:STEP:STEPS",
        parse=_isolate, text=Outage.text, repeat=True, default_text="none",
    )  # fmt: skip
    view: str | None = option(
        str, "serve a live view of the run at [HOST:]PORT (127.0.0.1 unless a host is given)",
        None, metavar="[HOST:]PORT", default_text="none",
    )  # fmt: skip
    # Last: its name would shadow `robot` (node.argsdecl.bounds) for the fields after it.
    robot: str = option(
        str, "the robot program: auto (the C++ robot where it was built and carries the "
        "run's middleware, else the Python robot), cpp, or python (the reference); "
        "testbed.run.robotchoice", "auto", choices=ROBOT_CHOICES, sweep={GRID, RUN},
        newer=True, grid=GridDim(13, str, VARIED),
    )  # fmt: skip

    @property
    def kills(self) -> tuple[tuple[int, int], ...]:
        """Every (robot, step) the run kills: --kill's, then the battery failure's."""
        planned = failures.battery_kill(self.battery_failure, self.robots, self.laser_range)
        return self.kill + ((planned,) if planned else ())

    def to_dict(self) -> dict:
        d = asdict(self)
        d["display_pos"] = list(self.display_pos) if self.display_pos else None
        d["snapshots"] = list(self.snapshots)
        d["kill"] = [f"{k}:{s}" for k, s in self.kill]
        d["isolate"] = [o.text() for o in self.isolate]
        return d

    @classmethod
    def from_dict(cls, d: dict) -> RunConfig:
        """The inverse of to_dict (a config as config.json, result.json or sweep.json hold it;
        keys left out take their defaults)."""
        kw = dict(d)
        if kw.get("display_pos") is not None:
            kw["display_pos"] = tuple(kw["display_pos"])
        if "snapshots" in kw:
            kw["snapshots"] = tuple(kw["snapshots"])
        if "kill" in kw:
            kw["kill"] = tuple(_kill(k) for k in kw["kill"])
        if "isolate" in kw:
            kw["isolate"] = tuple(_outage(o) for o in kw["isolate"])
        return cls(**kw)


OPTIONS = runoptions.options(RunConfig)
resultconfig.check_options(OPTIONS)  # result.json's config repeats those marked in_result
BY_NAME = {opt.name: opt for opt in OPTIONS}
# What `net up` shares with `run`: the network's options, the same flags and checks.
NET_OPTIONS = tuple(opt for opt in OPTIONS if opt.net)


def refusal(cfg: RunConfig) -> tuple[str, str] | None:
    """The first check joining options that `cfg` fails, as (the option it names, why in one
    line), or None: the one rule of `testbed run` (testbed.run.arguments.config_from_args), of a
    sweep file's runs (testbed.sweep.file) and of a plan in sweep.json
    (testbed.files.sweepstate). What this machine's programs can carry is
    testbed.run.arguments.refusal's."""
    cell = cfg.map_cell if cfg.map else CELL_M  # the empty terrain's cells are CELL_M
    if cfg.laser_range < cell:
        return "laser_range", (
            f"a laser range of {cfg.laser_range:g} m is shorter than a map cell "
            f"({cell:g} m): the robots would see nothing"
        )
    if cfg.laser_range / cell > MAX_LASER_CELLS:  # the robots refuse it (node.argsdecl)
        return "laser_range", (
            f"a laser range of {cfg.laser_range:g} m is over {MAX_LASER_CELLS:,} map cells of "
            f"{cell:g} m: use a coarser --map-cell or a shorter laser"
        )
    if cfg.wall_loss_pct is not None and cfg.range_model not in LOS_MODELS:
        return "wall_loss_pct", "--wall-loss is for the los range models: add --range-model los"
    for k, _ in cfg.kill:
        if not 1 <= k <= cfg.robots:
            return "kill", f"--kill names robot {k}, but the team is r1..r{cfg.robots}"
    why = failures.refusal(cfg.battery_failure, cfg.robots)
    if why:
        return "battery_failure", why
    for o in cfg.isolate:
        if not 1 <= o.robot <= cfg.robots:
            return "isolate", f"--isolate names robot {o.robot}, but the team is r1..r{cfg.robots}"
    if cfg.isolate and cfg.medium != VETH:
        return "isolate", ("--isolate needs the veth medium: on ns3-wifi the channel decides "
                           "who hears whom")  # fmt: skip
    why = maps_refusal(cfg.maps, cfg.middleware)
    if why:
        return "maps", why
    return None


def to_argv(cfg: RunConfig, always: Set[str] = frozenset()) -> list[str]:
    """`testbed run` arguments that give back `cfg` (without --out): see runoptions.to_argv."""
    return runoptions.to_argv(cfg, OPTIONS, always)
