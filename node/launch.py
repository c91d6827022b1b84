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
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from common.argtypes import number
from node import coordination
from node.displaysteps import VIDEO_EVERY
from node.flood import MODES
from node.messaging import DEFAULT as DEFAULT_MIDDLEWARE
from node.messaging import MIDDLEWARES
from node.messaging.maps import DEFAULT as DEFAULT_MAPS
from node.messaging.maps import MAPS
from topology.names import MAX_ROBOTS
from topology.spec import CELL_M

USAGE = "python -m node --robot r3 --robots 5 --body PATH ..."


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
    testbed.run.config takes the default and bounds of that option from here). No default:
    the flag is required."""  # fmt: skip
    meta = {"help": help, "kind": kind, "parse": parse, "above": above, "minimum": minimum,
            "maximum": maximum, "choices": choices, "run": run}  # fmt: skip
    return dataclasses.field(default=default, metadata={"arg": meta})


@dataclass(frozen=True)
class NodeArgs:
    """The robot's parameters: each declared once, here, with its default and bounds."""

    robot: int = arg(help="this robot, e.g. r3", parse=lambda t: robot_number(t))
    robots: int = arg(help="team size (exploring; the display is robots + 1)", kind=int,
                      above=0, maximum=MAX_ROBOTS)  # fmt: skip
    body: str = arg(help="Unix socket of the world's body link")
    role: str = arg("robot", "robot, or the display", choices=("robot", "display"))
    events: str | None = arg(None, "JSON-lines event log to append to")
    map_size: tuple[int, int] = arg((400, 400), "ROWSxCOLS cells", parse=lambda t: shape(t))
    cell: float = arg(CELL_M, "metres per map cell", kind=float, above=0)
    laser_range: float = arg(2.0, "laser range (m)", kind=float, above=0, run=True)
    laser_rays: int = arg(360, "rays of a laser scan", kind=int, minimum=4, run=True)
    speed: float = arg(0.1, "metres per step", kind=float, above=0, run=True)
    radius: float = arg(0.15, "the robot's radius (m)", kind=float, above=0, run=True)
    plan_period: int = arg(20, "steps between plans on the timer", kind=int, above=0, run=True)
    map_period: int = arg(10, "steps between map floods", kind=int, minimum=1, run=True)
    # A step of 10 s to one of 100 microseconds.
    time_scale: float = arg(1.0, "emulated time over wall time", kind=float, minimum=0.01,
                            maximum=1000.0, run=True)  # fmt: skip
    timer_phase: int = arg(0, "steps added to the first timer", kind=int)
    iface: str = arg("wlan0", "'' to not bind floods to a device")
    flood_port: int = arg(5100, "UDP port of the map floods", kind=int, above=0)
    flood: str = arg("pruned", "map flooding: self-pruning, or blind (every robot relays)",
                     choices=MODES, run=True)  # fmt: skip
    coordination: str = arg(coordination.DEFAULT, "goal coordination: the paper's rules read "
                            "literally, or ours (node.coordination)", choices=coordination.MODES,
                            run=True)  # fmt: skip
    goal_port: int = arg(5101, "port of the goal messages", kind=int, above=0)
    middleware: str = arg(DEFAULT_MIDDLEWARE, "what carries goals and re-plan requests "
                          "(node.messaging)", choices=MIDDLEWARES, run=True)  # fmt: skip
    maps: str = arg(DEFAULT_MAPS, "map sharing: UDP floods, or the middleware's publish/"
                    "subscribe (zenoh, dds; node.messaging.maps)", choices=MAPS,
                    run=True)  # fmt: skip
    bind: str | None = arg(None, "address for the goal socket (default: the robot's)")
    out_dir: str | None = arg(None, "display: where snapshots and the video go")
    snapshots: frozenset[int] = arg(frozenset(), "display: steps, e.g. 100,500",
                                    parse=lambda t: steps(t))  # fmt: skip
    video_every: int = arg(VIDEO_EVERY, "display: steps between video frames", kind=int, above=0)

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
    """`python -m node`'s parser, made from NodeArgs' fields (dest: the field's name)."""
    p = _Parser(prog="python -m node", description=USAGE)
    for f in dataclasses.fields(NodeArgs):
        meta = f.metadata["arg"]
        flag = "--" + f.name.replace("_", "-")
        kw: dict[str, Any] = {"dest": f.name, "help": meta["help"]}
        if meta["parse"] is not None:
            kw["type"] = meta["parse"]
        elif meta["kind"] is not None:
            kw["type"] = number(meta["kind"], flag, above=meta["above"], minimum=meta["minimum"],
                                magnitude=meta["maximum"])  # fmt: skip
        if meta["choices"] is not None:
            kw["choices"] = meta["choices"]
        if f.default is dataclasses.MISSING:
            kw["required"] = True
        else:
            kw["default"] = f.default
        p.add_argument(flag, **kw)
    return p


def run_params() -> dict[str, dataclasses.Field]:
    """The fields a run passes through from its RunConfig fields of the same names."""
    return {f.name: f for f in dataclasses.fields(NodeArgs) if f.metadata["arg"]["run"]}


def bounds(name: str) -> dict:
    """The default and bounds of robot parameter `name`, for the run option that sets it."""
    f = {f.name: f for f in dataclasses.fields(NodeArgs)}[name]
    meta = f.metadata["arg"]
    out = {"default": f.default}
    out.update(
        {k: meta[k] for k in ("above", "minimum", "maximum", "choices") if meta[k] is not None}
    )
    return out
