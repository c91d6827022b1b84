"""The robot process's command line: one dataclass, `NodeArgs`, and the parser that reads it.

`testbed run` builds a `NodeArgs` for each robot and the display and turns it into argv with
`to_argv()`; `python -m node` parses argv back into a `NodeArgs` with `NodeArgs.parse()`.
The dataclass's fields, declared in node.argsdecl (`Params`, a module that loads no planner
or step core, which the run option table reads), are the parser's destinations, one for one
(a unit test holds them together), so the two sides cannot drift apart. Bad arguments: one
line, exit 2.

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
import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from common.argtypes import number

# The declarations, re-exported: node.argsgen, the tests and older callers read them here.
from node.argsdecl import (  # noqa: F401
    MAX_LASER_CELLS,
    MAX_RANGE_M,
    REAL,
    ROBOT_DIGITS,
    SHAPE_DIGITS,
    WHOLE,
    WHOLE_MAX,
    Params,
    _within_whole_max,
    bounds,
    maps_refusal,
    run_params,
)

USAGE = "python -m node --robot r3 --robots 5 --body PATH ..."
HELP_FLAGS = ("-h", "--help")
# Parse and check the arguments, then exit 0 with nothing run: how tests ask either robot
# whether it takes a command line (tests/unit/test_robot_cli_contract.py).
CHECK_FLAG = "--check-args"
CHECK_HELP = "parse and check the arguments, then exit 0 (nothing runs)"


@dataclass(frozen=True)
class NodeArgs(Params):
    """The robot's parameters (node.argsdecl.Params: each declared once there, with its default
    and bounds), read from a command line and checked across flags."""

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
