"""The declarations of the robot's parameters, in a module that loads nothing heavy: each
NodeArgs field's default, help, how its text is read and its bounds (`Params`), the numbers
they use, the choices of the parameters with a fixed set of values and the rule joining
--maps and --middleware (`maps_refusal`). node.launch's NodeArgs is `Params` with its
parser and checks across flags; testbed.files.runconfig takes a run option's default and
bounds from here (`bounds`), so the option table loads no planner, step core, numpy or ctypes
(tests/unit/test_import_budget.py). What this imports: only the standard library, common/,
topology's constants, node.messaging's registry (data) and node.displaysteps.
"""

from __future__ import annotations

import argparse
import dataclasses
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from common import timescale
from node.displaysteps import VIDEO_EVERY
from node.messaging import DEFAULT as DEFAULT_MIDDLEWARE
from node.messaging import DEFAULT_MAPS, MIDDLEWARES, REGISTRY
from topology.names import MAX_ROBOTS
from topology.spec import CELL_M

# The longest laser a run may have: the range class of 2-D lidars (30 m, e.g. Hokuyo's
# UTM-30LX); a robot's scan without tables takes about 3 ms here at that range (node.rays).
MAX_RANGE_M = 30.0
# Goal coordination: the paper's rules read literally, or ours (node.coordination).
COORDINATIONS = ("paper", "ours")
DEFAULT_COORDINATION = "ours"
# Map flooding: self-pruning, or blind (node.flood).
FLOODS = ("pruned", "blind")
# How maps are shared (node.messaging.maps): UDP floods, or the middleware's topics, which
# the middlewares with a map topic in the registry have.
MAPS = ("flood", "pubsub")
PUBSUB_MIDDLEWARES = tuple(n for n, e in REGISTRY.items() if e.map_topic is not None)


def maps_refusal(maps: str, middleware: str) -> str | None:
    """Why `--maps maps` cannot go with `--middleware middleware` (one line), or None."""
    if maps == "pubsub" and middleware not in PUBSUB_MIDDLEWARES:
        return (
            f"--maps pubsub needs --middleware {' or '.join(PUBSUB_MIDDLEWARES)} "
            f"(not {middleware}): maps are published on their topics"
        )
    return None


# Every whole number is within +-10^9: the C++ robot holds them in 32-bit ints, and no step
# count of a run comes near (testbed.files.runconfig.MAX_STEPS is 10^7).
WHOLE_MAX = 10**9
WHOLE = re.compile(r"-?[0-9]+")
REAL = re.compile(r"-?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][-+]?[0-9]+)?")
ROBOT_DIGITS = 3  # r1 .. r999
SHAPE_DIGITS = 5  # a side of at most 99,999 cells
# A laser ray of at most this many cells: beyond, the laser's tables and cell indices outgrow
# what either robot holds (the Python robot's int32 indices overflow at about 23,000).
MAX_LASER_CELLS = 10_000
# A cell of at least a millimetre: positions in cells stay far from int32's end.
MIN_CELL_M = 0.001
# A robot of at most 10 m: its footprint in cells stays an int (the planner inflates by it).
MAX_RADIUS_M = 10.0
MAX_PORT = 65535


def _within_whole_max(digits: str) -> bool:
    """Whether digits (an optional '-' and [0-9]+) are within +-WHOLE_MAX, however many zeros
    lead (without converting thousands of digits)."""
    significant = digits.lstrip("-").lstrip("0")
    return len(significant) <= len(str(WHOLE_MAX)) and int(significant or "0") <= WHOLE_MAX


def robot_number(text: str) -> int:
    """`r3` or `3`: a robot's number, 1 to 999."""
    m = re.fullmatch(rf"r?([0-9]{{1,{ROBOT_DIGITS}}})", text)
    if not m or int(m[1]) < 1:
        raise argparse.ArgumentTypeError(f"{text!r} is not a robot name like r3")
    return int(m[1])


def shape(text: str) -> tuple[int, int]:
    """`ROWSxCOLS`, each 1 to 99,999."""
    side = rf"([0-9]{{1,{SHAPE_DIGITS}}})"
    m = re.fullmatch(rf"{side}x{side}", text)
    if not m or int(m[1]) < 1 or int(m[2]) < 1:
        raise argparse.ArgumentTypeError(f"{text!r} is not ROWSxCOLS")
    return int(m[1]), int(m[2])


def steps(text: str) -> frozenset[int]:
    """Comma-separated steps, each 0 to WHOLE_MAX in digits; empty parts are skipped."""
    parts = [s for s in text.split(",") if s]
    if not all(re.fullmatch(r"[0-9]+", s) and _within_whole_max(s) for s in parts):
        raise argparse.ArgumentTypeError(f"{text!r} is not a list of steps")
    return frozenset(int(s) for s in parts)


def arg(
    default=dataclasses.MISSING,
    help: str = "",
    *,
    kind: type | None = None,
    parse: Callable[[str], Any] | None = None,
    above: float | None = None,
    minimum: float | None = None,
    maximum: float | None = None,
    choices: tuple[str, ...] | None = None,
    run: bool = False,
) -> Any:
    """A NodeArgs field and its flag: the default, the help, how the text is read (`parse`, or a
    number of `kind` within `above`/`minimum`/`maximum`, or one of `choices`), and whether a run
    passes its RunConfig field of the same name through (`run`: testbed.run.execute does, and
    testbed.files.runconfig takes the default and bounds of that option from here). No default:
    the flag is required."""  # fmt: skip
    meta = {"help": help, "kind": kind, "parse": parse, "above": above, "minimum": minimum,
            "maximum": maximum, "choices": choices, "run": run}  # fmt: skip
    return dataclasses.field(default=default, metadata={"arg": meta})


@dataclass(frozen=True)
class Params:
    """The robot's parameters: each declared once, here, with its default and bounds
    (node.launch.NodeArgs adds the parser and the checks across flags)."""

    robot: int = arg(help="this robot, e.g. r3", parse=robot_number)
    robots: int = arg(help="team size (exploring; the display is robots + 1)", kind=int,
                      above=0, maximum=MAX_ROBOTS)  # fmt: skip
    body: str = arg(help="Unix socket of the world's body link")
    role: str = arg("robot", "robot, or the display", choices=("robot", "display"))
    events: str | None = arg(None, "JSON-lines event log to append to")
    map_size: tuple[int, int] = arg((400, 400), "ROWSxCOLS cells", parse=shape)
    cell: float = arg(CELL_M, "metres per map cell (at least 1 mm)", kind=float,
                      minimum=MIN_CELL_M)  # fmt: skip
    # Its bounds across flags are NodeArgs.refusal's: a run option takes its own maximum.
    laser_range: float = arg(2.0, f"laser range (m): at least a cell, at most {MAX_RANGE_M:g} m "
                             f"and {MAX_LASER_CELLS:,} cells", kind=float, above=0,
                             run=True)  # fmt: skip
    laser_rays: int = arg(360, "rays of a laser scan", kind=int, minimum=4, run=True)
    speed: float = arg(0.1, "metres per step", kind=float, above=0, run=True)
    radius: float = arg(0.15, f"the robot's radius (m, at most {MAX_RADIUS_M:g})", kind=float,
                        above=0, maximum=MAX_RADIUS_M, run=True)  # fmt: skip
    plan_period: int = arg(20, "steps between plans on the timer", kind=int, above=0, run=True)
    map_period: int = arg(10, "steps between map floods", kind=int, minimum=1, run=True)
    # A step of 10 s to one of 100 microseconds (common.timescale).
    time_scale: float = arg(1.0, "emulated time over wall time", kind=float,
                            minimum=timescale.MIN, maximum=timescale.MAX, run=True)  # fmt: skip
    timer_phase: int = arg(0, "steps added to the first timer", kind=int)
    iface: str = arg("wlan0", "'' to not bind floods to a device")
    flood_port: int = arg(5100, "UDP port of the map floods", kind=int, above=0,
                          maximum=MAX_PORT)  # fmt: skip
    flood: str = arg("pruned", "map flooding: self-pruning, or blind (every robot relays)",
                     choices=FLOODS, run=True)  # fmt: skip
    coordination: str = arg(DEFAULT_COORDINATION, "goal coordination: the paper's rules read "
                            "literally, or ours (node.coordination)", choices=COORDINATIONS,
                            run=True)  # fmt: skip
    goal_port: int = arg(5101, "port of the goal messages", kind=int, above=0,
                         maximum=MAX_PORT)  # fmt: skip
    middleware: str = arg(DEFAULT_MIDDLEWARE, "what carries goals and re-plan requests "
                          "(node.messaging)", choices=MIDDLEWARES, run=True)  # fmt: skip
    maps: str = arg(DEFAULT_MAPS, "map sharing: UDP floods, or the middleware's publish/"
                    "subscribe (zenoh, dds; node.messaging.maps)", choices=MAPS,
                    run=True)  # fmt: skip
    bind: str | None = arg(None, "address for the goal socket (default: the robot's)")
    out_dir: str | None = arg(None, "display: where snapshots and the video go")
    snapshots: frozenset[int] = arg(frozenset(), "display: steps, e.g. 100,500",
                                    parse=steps)  # fmt: skip
    video_every: int = arg(VIDEO_EVERY, "display: steps between video frames", kind=int, above=0)


def run_params() -> dict[str, dataclasses.Field]:
    """The fields a run passes through from its RunConfig fields of the same names."""
    return {f.name: f for f in dataclasses.fields(Params) if f.metadata["arg"]["run"]}


def bounds(name: str) -> dict:
    """The default and bounds of robot parameter `name`, for the run option that sets it."""
    f = {f.name: f for f in dataclasses.fields(Params)}[name]
    meta = f.metadata["arg"]
    out = {"default": f.default}
    out.update(
        {k: meta[k] for k in ("above", "minimum", "maximum", "choices") if meta[k] is not None}
    )
    return out
