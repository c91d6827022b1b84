"""The robot process's command line: one dataclass, `NodeArgs`, and the parser that reads it.

`testbed run` builds a `NodeArgs` for each robot and the display and turns it into argv with
`to_argv()`; `python -m node` parses argv back into a `NodeArgs` with `NodeArgs.parse()`.
The dataclass's fields are the parser's destinations, one for one (a unit test holds them
together), so the two sides cannot drift apart. Bad arguments: one line, exit 2.

The C++ robot (build/tb-robot) reads the same command line: node.argsgen writes NodeArgs'
flags, types, bounds, defaults, help and the checks' numbers into a header at build time
(build/gen/node_args.h), and native/robot/args.cc checks from that table. What both read is
stated here and in docs/robot-contract.md section 5; tests/unit/test_robot_cli_contract.py
feeds the same hostile argument lists to both.

- A flag's value is the next argument, whatever it is (`--timer-phase -5`, `--body -x`), or
  follows '=' (`--body=-x`). `-h`/`--help` anywhere else: the listing, exit 0.
  `--check-args`: parse and check, then exit 0 (nothing runs).
- A whole number is an optional '-' and ASCII digits, within +-WHOLE_MAX (no blanks, '+' or
  '_'); a real is an optional '-', ASCII digits with an optional '.' and exponent, finite.
- Then each flag's bounds (`above`: exclusive; `minimum`: inclusive; `maximum`: a bound of
  the magnitude), then the checks across flags (`NodeArgs.refusal`).
"""

from __future__ import annotations

import argparse
import dataclasses
import re
import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from common import timescale
from common.argtypes import number
from node import coordination
from node.displaysteps import VIDEO_EVERY
from node.flood import MODES
from node.messaging import DEFAULT as DEFAULT_MIDDLEWARE
from node.messaging import MIDDLEWARES
from node.messaging.maps import DEFAULT as DEFAULT_MAPS
from node.messaging.maps import MAPS
from node.messaging.maps import refusal as maps_refusal
from node.rays import MAX_RANGE_M
from topology.names import MAX_ROBOTS
from topology.spec import CELL_M

USAGE = "python -m node --robot r3 --robots 5 --body PATH ..."
HELP_FLAGS = ("-h", "--help")
# Parse and check the arguments, then exit 0 with nothing run: how tests ask either robot
# whether it takes a command line (tests/unit/test_robot_cli_contract.py).
CHECK_FLAG = "--check-args"
CHECK_HELP = "parse and check the arguments, then exit 0 (nothing runs)"
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
class NodeArgs:
    """The robot's parameters: each declared once, here, with its default and bounds."""

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
                     choices=MODES, run=True)  # fmt: skip
    coordination: str = arg(coordination.DEFAULT, "goal coordination: the paper's rules read "
                            "literally, or ours (node.coordination)", choices=coordination.MODES,
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

    @classmethod
    def parse(cls, argv: list[str] | None = None) -> NodeArgs:
        """From a command line; bad arguments print one line and exit with status 2, `--help`
        prints the listing and `--check-args` exits 0 once they are checked."""
        p = parser()
        tokens, check = _tokens(p, sys.argv[1:] if argv is None else argv)
        args = cls(**vars(p.parse_args(tokens)))
        why = args.refusal()
        if why:
            p.error(why)
        if check:
            sys.exit(0)
        return args

    def refusal(self) -> str | None:
        """What is wrong across flags (one line), or None; each flag's own bounds are its
        declaration's. The numbers are MAX_RANGE_M, MAX_LASER_CELLS and PUBSUB_MIDDLEWARES,
        which node.argsgen gives the C++ robot's twin of this check (args.cc)."""
        if not self.cell <= self.laser_range <= MAX_RANGE_M:
            return (f"--laser-range {self.laser_range!r} must be at least a cell "
                    f"({self.cell!r} m) and at most {MAX_RANGE_M:g} m")  # fmt: skip
        if self.laser_range / self.cell > MAX_LASER_CELLS:
            return (f"--laser-range {self.laser_range!r} is more than {MAX_LASER_CELLS:,} "
                    f"cells of {self.cell!r} m")  # fmt: skip
        if self.role == "display" and not self.out_dir:
            return "the display needs --out-dir"
        return maps_refusal(self.maps, self.middleware)

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


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, exit 2
        sys.stderr.write(f"node: {message}\n")
        sys.exit(2)


def _number(kind: type, flag: str, meta: dict) -> Callable[[str], Any]:
    """The argparse type of a number flag: the contract's spelling (WHOLE, REAL; a whole
    number within +-WHOLE_MAX), then common.argtypes.number's checks and the flag's bounds."""
    check = number(kind, flag, above=meta["above"], minimum=meta["minimum"],
                   magnitude=meta["maximum"])  # fmt: skip

    def parse(text: str) -> Any:
        whole = kind is int
        if not (WHOLE if whole else REAL).fullmatch(text):
            noun = "a whole number" if whole else "a number"
            raise argparse.ArgumentTypeError(f"{flag} must be {noun}, not {text!r}")
        if not whole:
            return check(text)
        if not _within_whole_max(text):
            raise argparse.ArgumentTypeError(
                f"{flag} must be within {WHOLE_MAX:,} of 0, not {text}"
            )
        sign, digits = ("-", text[1:]) if text.startswith("-") else ("", text)
        return check(sign + (digits.lstrip("0") or "0"))  # int() takes 4,300 digits at most

    return parse


def parser(prog: str = "python -m node") -> argparse.ArgumentParser:
    """`python -m node`'s parser, made from NodeArgs' fields (dest: the field's name). The
    listing is 100 columns wide wherever it is printed: tb-robot prints the same."""
    p = _Parser(prog=prog, description=USAGE, allow_abbrev=False,
                formatter_class=lambda prog: argparse.HelpFormatter(prog, width=100))  # fmt: skip
    for f in dataclasses.fields(NodeArgs):
        meta = f.metadata["arg"]
        flag = "--" + f.name.replace("_", "-")
        kw: dict[str, Any] = {"dest": f.name, "help": meta["help"]}
        if meta["parse"] is not None:
            kw["type"] = meta["parse"]
        elif meta["kind"] is not None:
            kw["type"] = _number(meta["kind"], flag, meta)
        if meta["choices"] is not None:
            kw["choices"] = meta["choices"]
        if f.default is dataclasses.MISSING:
            kw["required"] = True
        else:
            kw["default"] = f.default
        p.add_argument(flag, **kw)
    return p


def listing(prog: str = "python -m node") -> str:
    """What `--help` prints: the parser's listing with CHECK_FLAG (which NodeArgs.parse reads
    itself, as it does `--help`)."""
    p = parser(prog)
    p.add_argument(CHECK_FLAG, action="store_true", help=CHECK_HELP)
    return p.format_help()


def _tokens(p: argparse.ArgumentParser, argv: list[str]) -> tuple[list[str], bool]:
    """argv as `--flag=value` tokens, so argparse never guesses whether an argument is a value
    (it would take `-1e10` for a flag, and `-5` for a value); and whether CHECK_FLAG was
    given. `--help` prints the listing and exits 0; an argument that is neither a flag nor a
    flag's value: one line, exit 2."""
    flags = {"--" + f.name.replace("_", "-") for f in dataclasses.fields(NodeArgs)}
    tokens, unknown, check, i = [], [], False, 0
    while i < len(argv):
        token, i = argv[i], i + 1
        name = token.split("=", 1)[0] if token.startswith("--") else token
        if token in HELP_FLAGS:
            sys.stdout.write(listing(p.prog))
            sys.exit(0)
        elif token == CHECK_FLAG:
            check = True
        elif name not in flags:
            unknown.append(token)
        elif "=" in token:
            tokens.append(token)
        elif i < len(argv):
            tokens.append(f"{token}={argv[i]}")
            i += 1
        else:
            p.error(f"argument {token}: expected one argument")
    if unknown:
        p.error(f"unrecognized arguments: {' '.join(repr(u) for u in unknown)}")
    return tokens, check


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
