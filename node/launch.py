"""The robot process's command line: one dataclass, `NodeArgs`, and the parser that reads it.

`testbed run` builds a `NodeArgs` for each robot and the display and turns it into argv with
`to_argv()`; `python -m node` parses argv back into a `NodeArgs` with `NodeArgs.parse()`.
The dataclass's fields are the parser's destinations, one for one (a unit test holds them
together), so the two sides cannot drift apart. Bad arguments: one line, exit 2.
"""

from __future__ import annotations

import argparse
import dataclasses
import re
import sys
from dataclasses import dataclass

from node import coordination
from node.flood import MODES
from node.messaging import DEFAULT as DEFAULT_MIDDLEWARE
from node.messaging import MIDDLEWARES
from node.messaging.maps import DEFAULT as DEFAULT_MAPS
from node.messaging.maps import MAPS
from topology.argtypes import number

USAGE = "python -m node --robot r3 --robots 5 --body PATH ..."


@dataclass(frozen=True)
class NodeArgs:
    robot: int
    robots: int  # team size (exploring robots; the display is robots + 1)
    body: str  # the Unix socket of the world's body link
    role: str = "robot"  # or "display"
    events: str | None = None  # JSON-lines event log to append to
    map_size: tuple[int, int] = (400, 400)  # rows, columns
    cell: float = 0.05  # metres per map cell
    laser_range: float = 2.0
    laser_rays: int = 360
    speed: float = 0.1  # metres per step
    radius: float = 0.15
    plan_period: int = 20  # steps between plans on the timer
    map_period: int = 10  # steps between map floods
    time_scale: float = 1.0
    timer_phase: int = 0  # steps added to the first timer period
    iface: str = "wlan0"  # '' to not bind floods to a device
    flood_port: int = 5100
    flood: str = "pruned"
    coordination: str = coordination.DEFAULT  # how goals are agreed: "paper" or "ours"
    goal_port: int = 5101
    middleware: str = DEFAULT_MIDDLEWARE  # what carries goals and requests (node.messaging)
    maps: str = DEFAULT_MAPS  # how maps are shared: floods, or the middleware's pub/sub
    bind: str | None = None  # address for the goal socket (default: the robot's)
    out_dir: str | None = None  # display: where snapshots and the video go
    snapshots: frozenset[int] = frozenset()  # display: steps with a PNG snapshot
    video_every: int = 10  # display: steps between video frames

    @classmethod
    def parse(cls, argv: list[str] | None = None) -> NodeArgs:
        """From a command line; bad arguments print one line and exit with status 2."""
        ns = parser().parse_args(argv)
        return cls(**vars(ns))

    def to_argv(self) -> list[str]:
        """The command line that parses back into this NodeArgs (every field that is set)."""
        argv = []
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if value is None:
                continue
            argv += ["--" + f.name.replace("_", "-"), _text(f.name, value)]
        return argv


def _text(name: str, value) -> str:
    if name == "robot":
        return f"r{value}"
    if name == "map_size":
        return f"{value[0]}x{value[1]}"
    if name == "snapshots":
        return ",".join(str(s) for s in sorted(value))
    return repr(value) if isinstance(value, float) else str(value)


def robot_number(text: str) -> int:
    m = re.fullmatch(r"r?(\d{1,3})", text)
    if not m or int(m[1]) < 1:
        raise argparse.ArgumentTypeError(f"{text!r} is not a robot name like r3")
    return int(m[1])


def shape(text: str) -> tuple[int, int]:
    m = re.fullmatch(r"(\d{1,5})x(\d{1,5})", text)
    if not m or int(m[1]) < 1 or int(m[2]) < 1:
        raise argparse.ArgumentTypeError(f"{text!r} is not ROWSxCOLS")
    return int(m[1]), int(m[2])


def steps(text: str) -> frozenset[int]:
    try:
        return frozenset(int(s) for s in text.split(",") if s.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a list of steps") from None


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, exit 2
        sys.stderr.write(f"node: {message}\n")
        sys.exit(2)


def parser() -> argparse.ArgumentParser:
    p = _Parser(prog="python -m node", description=USAGE)
    p.add_argument("--robot", type=robot_number, required=True)
    p.add_argument(
        "--robots",
        type=number(int, "--robots", above=0),
        required=True,
        help="team size (exploring)",
    )
    p.add_argument("--role", choices=("robot", "display"), default="robot")
    p.add_argument("--body", required=True, help="Unix socket of the world's body link")
    p.add_argument("--events", help="JSON-lines event log to append to")
    p.add_argument("--map-size", type=shape, default=(400, 400), help="ROWSxCOLS cells")
    p.add_argument("--cell", type=number(float, "--cell", above=0), default=0.05)
    p.add_argument("--laser-range", type=number(float, "--laser-range", above=0), default=2.0)
    p.add_argument("--laser-rays", type=number(int, "--laser-rays", above=0), default=360)
    p.add_argument(
        "--speed", type=number(float, "--speed", above=0), default=0.1, help="metres per step"
    )
    p.add_argument("--radius", type=number(float, "--radius", above=0), default=0.15)
    p.add_argument("--plan-period", type=number(int, "--plan-period", above=0), default=20)
    p.add_argument("--map-period", type=number(int, "--map-period", above=0), default=10)
    p.add_argument("--time-scale", type=number(float, "--time-scale", above=0), default=1.0)
    p.add_argument("--timer-phase", type=int, default=0, help="steps added to the first timer")
    p.add_argument("--iface", default="wlan0", help="'' to not bind floods to a device")
    p.add_argument("--flood-port", type=number(int, "--flood-port", above=0), default=5100)
    p.add_argument(
        "--flood",
        choices=MODES,
        default="pruned",
        help="map flooding: self-pruning (default) or blind (every robot relays)",
    )
    p.add_argument(
        "--coordination",
        choices=coordination.MODES,
        default=coordination.DEFAULT,
        help="goal coordination: the paper's rules read literally, or ours (node.coordination)",
    )
    p.add_argument("--goal-port", type=number(int, "--goal-port", above=0), default=5101)
    p.add_argument(
        "--middleware",
        choices=MIDDLEWARES,
        default=DEFAULT_MIDDLEWARE,
        help="what carries goals and re-plan requests (node.messaging)",
    )
    p.add_argument(
        "--maps",
        choices=MAPS,
        default=DEFAULT_MAPS,
        help="map sharing: UDP floods (default) or the middleware's publish/subscribe "
        "(zenoh, dds; node.messaging.maps)",
    )
    p.add_argument("--bind", help="address for the goal socket (default: the robot's)")
    p.add_argument("--out-dir", help="display: where snapshots and the video go")
    p.add_argument(
        "--snapshots", type=steps, default=frozenset(), help="display: steps, e.g. 100,500"
    )
    p.add_argument("--video-every", type=number(int, "--video-every", above=0), default=10)
    return p
