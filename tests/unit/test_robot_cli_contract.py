"""One command line, two robots (docs/robot-contract.md section 5): the same hostile argument
lists go to the Python robot's parser (node.launch.NodeArgs.parse, which `python -m node`
runs first) and to build/tb-robot, each with `--check-args` (parse, check, exit 0: nothing
runs), and both must give the same status: 0 for a command line they take, 2 with one line
for one they refuse. The lists: the cases issue 55 found, each numeric flag at and just
beyond each of its bounds as NodeArgs declares them, spellings Python's int() and float()
would take (blanks, '+', '_', other scripts' digits) and C++'s strtod would (hex), NaN,
infinities, -0, huge exponents, empty values, missing values, unknown flags, duplicates,
and `--help` (the same listing, exit 0). No root needed; the C++ half is skipped where
build/tb-robot was not built.
"""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
from functools import cache

import pytest

from common.paths import PROJECT_ROOT
from node import launch
from node.launch import WHOLE_MAX, NodeArgs
from node.native import TB_ROBOT, unbuilt_reason

BASE = ["--robot", "r1", "--robots", "2", "--body", "/nonexistent/body.sock"]


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def _real(value: float) -> str:
    return repr(float(value))


def _beyond(meta: dict, whole: bool) -> list[str]:
    """Values at and just beyond each of a number flag's bounds."""
    out: list[float | int] = []
    down, up = (lambda v: v - 1, lambda v: v + 1) if whole else (
        lambda v: math.nextafter(v, -math.inf), lambda v: math.nextafter(v, math.inf))  # fmt: skip
    if meta["above"] is not None:
        out += [meta["above"], up(meta["above"])]
    if meta["minimum"] is not None:
        out += [meta["minimum"], down(meta["minimum"])]
    if meta["maximum"] is not None:
        out += [meta["maximum"], up(meta["maximum"]), -meta["maximum"], down(-meta["maximum"])]
    if whole:
        out += [WHOLE_MAX, WHOLE_MAX + 1, -WHOLE_MAX, -WHOLE_MAX - 1]
        return [str(int(v)) for v in out]
    return [_real(v) for v in out]


# Spellings of a number that one parser or another might take.
NUMBER_SPELLINGS = ["nan", "NaN", "inf", "-inf", "Infinity", "-0", "-0.0", "0", "", " ", "1e999",
                    "-1e999", "1e-999", "1e99999999999999999999", "1_000", " 5", "5 ", "+5",
                    "0x10", "0x1p3", "1e3", "1.5", "1.", ".5", "-.5e-3", "\uff15", "\u0663",
                    "5\n", "0005", "-", "e5", "1e", "1e+", "--5", "9" * 400, "9" * 5000,
                    "1" + "0" * 23, "0" * 30 + "7", "0" * 5000 + "1"]  # fmt: skip


def _generated() -> list[tuple[str, list[str]]]:
    """Cases made from NodeArgs' declaration: every flag with the hostile spellings, every
    number at and beyond its bounds, every choice and a few that are not."""
    cases = []
    for f in dataclasses.fields(NodeArgs):
        meta, flag = f.metadata["arg"], _flag(f.name)
        values: list[str] = []
        if meta["kind"] in (int, float):
            values += _beyond(meta, meta["kind"] is int) + NUMBER_SPELLINGS
        elif meta["choices"] is not None:
            values += [*meta["choices"], "", meta["choices"][0].upper(), meta["choices"][0] + " "]
        else:
            values += ["", "-x", "--help", "--robot", "\udcff", "a b"]
        for v in values:
            rest = _without(BASE, flag) if flag in BASE else BASE
            shown = repr(v) if len(v) <= 40 else f"{v[:8]!r}... ({len(v)} characters)"
            cases.append((f"{flag} {shown}", [*rest, flag, v]))
            cases.append((f"{flag}={shown}", [*rest, f"{flag}={v}"]))
    return cases


def _without(argv: list[str], flag: str) -> list[str]:
    i = argv.index(flag)
    return argv[:i] + argv[i + 2 :]


# issue 55's disagreements, and the values that broke a robot, with the verdict both give now.
ISSUE = [
    ("--time-scale", "0.001", 2), ("--time-scale", "1e-300", 2), ("--time-scale", "1001", 2),
    ("--plan-period", "1e10", 2), ("--plan-period", "10000000000", 2), ("--cell", "1e-300", 2),
    ("--timer-phase", "-1e10", 2), ("--timer-phase", "-10000000000", 2),
    ("--timer-phase", "-5", 0), ("--snapshots", "1" * 23, 2), ("--snapshots", "100,500", 0),
    ("--laser-range", "1e9", 2), ("--laser-range", "30", 0), ("--laser-range", "30.000001", 2),
    ("--laser-range", "0.01", 2), ("--laser-range", "1e30", 2), ("--radius", "1e300", 2),
    ("--goal-port", "70000", 2), ("--flood-port", "65535", 0),
]  # fmt: skip

HAND = [
    ("nothing", []),
    ("base", BASE),
    ("missing --body", BASE[:4]),
    ("missing value at the end", [*BASE, "--robots"]),
    ("missing value, inline empty", [*BASE, "--robots="]),
    ("unknown flag", [*BASE, "--bogus", "1"]),
    ("unknown flag, inline", [*BASE, "--bogus=1"]),
    ("abbreviation", [*_without(BASE, "--body"), "--bo", "b"]),
    ("positional", [*BASE, "extra"]),
    ("double dash", [*BASE, "--"]),
    ("double dash as a value", [*_without(BASE, "--body"), "--body", "--"]),
    ("single dash flag", [*BASE, "-x"]),
    ("duplicate, last good", [*BASE, "--robots", "0", "--robots", "3"]),
    ("duplicate, last bad", [*BASE, "--robots", "3", "--robots", "0"]),
    ("duplicate --check-args", [*BASE, "--check-args"]),
    ("--check-args with a value", [*BASE, "--check-args=1"]),
    ("flag as a value", ["--robot", "--robots", "2", "--body", "b"]),
    ("display without --out-dir", [*BASE, "--role", "display"]),
    ("display with --out-dir", [*BASE, "--role", "display", "--out-dir", "/tmp/x"]),
    ("pubsub with nanomsg", [*BASE, "--maps", "pubsub"]),
    ("pubsub with zenoh", [*BASE, "--maps", "pubsub", "--middleware", "zenoh"]),
    ("laser of one cell", [*BASE, "--cell", "0.5", "--laser-range", "0.5"]),
    ("laser under a cell", [*BASE, "--cell", "0.5", "--laser-range", "0.4999"]),
    ("laser of 10,000 cells", [*BASE, "--cell", "0.002", "--laser-range", "20"]),
    ("laser of 10,001 cells", [*BASE, "--cell", "0.002", "--laser-range", "20.002"]),
    ("every field", NodeArgs(robot=7, robots=9, body="b", role="display", events="e",
                             map_size=(300, 250), cell=0.1, laser_range=1.5, laser_rays=180,
                             speed=0.075, radius=0.2, plan_period=15, map_period=7,
                             time_scale=3.75, timer_phase=11, iface="", flood_port=6000,
                             flood="blind", coordination="paper", goal_port=6001,
                             middleware="zenoh", maps="pubsub", bind="127.0.0.1", out_dir="d",
                             snapshots=frozenset({600, 200}), video_every=4).to_argv()),
    *[(f"robot {v!r}", ["--robot", v, *BASE[2:]])
      for v in ["r0", "r1", "1", "r999", "r1000", "R1", "r01", "r\u0663", "r 1", "r-1", "", "rr1"]],
    *[(f"map size {v!r}", [*BASE, "--map-size", v])
      for v in ["400x400", "0x1", "1x99999", "100000x1", "4x", "x4", "4X4", " 4x4", "4x4x4"]],
    *[(f"snapshots {v!r}", [*BASE, "--snapshots", v])
      for v in ["", ",", "1,,2", " 1", "-1", "1e3", "1000000000", "1000000001", "1,x"]],
    *[(f"{flag} {v}", [*BASE, flag, v]) for flag, v, _ in ISSUE],
]  # fmt: skip

HELP = [
    ("-h", ["-h"]),
    ("--help", ["--help"]),
    ("--help after a bad value", [*BASE, "--robots", "0", "--help"]),
    ("--help after an unknown flag", ["--bogus", "--help"]),
]
NOT_HELP = [
    ("--help=1", ["--help=1"]),
    ("-hh", ["-hh"]),
    ("--he", ["--he"]),
    ("--help as a value", [*_without(BASE, "--body"), "--body", "--help"]),
]

CASES = HAND + _generated() + NOT_HELP


def python_status(argv: list[str]) -> int:
    """NodeArgs.parse's exit status (as `python -m node`'s, which calls it first)."""
    try:
        NodeArgs.parse(argv)
    except SystemExit as e:
        return int(e.code or 0)
    return 0


@cache
def cpp_reason() -> str | None:
    """Why the C++ half cannot run, or None."""
    why = unbuilt_reason()
    if why is not None:
        return f"build/tb-robot not built: {why}"
    p = subprocess.run([str(TB_ROBOT), "--check-args", *BASE], capture_output=True, timeout=20)
    if p.returncode != 0:
        return f"build/tb-robot predates --check-args (run make build/tb-robot): {p.stderr!r}"
    return None


def cpp_run(argv: list[str]) -> subprocess.CompletedProcess:
    reason = cpp_reason()
    if reason is not None:
        pytest.skip(reason)
    return subprocess.run([str(TB_ROBOT), *argv], capture_output=True, timeout=20)


@pytest.mark.parametrize("argv", [c[1] for c in CASES], ids=[c[0] for c in CASES])
def test_both_robots_give_the_same_status(argv, capsys):
    argv = ["--check-args", *argv]
    py = python_status(argv)
    err = capsys.readouterr().err.splitlines()
    assert py in (0, 2)
    if py == 2:
        assert len(err) == 1 and err[0].startswith("node: "), err
    p = cpp_run(argv)
    assert p.returncode == py, f"python {py}, tb-robot {p.returncode}: {p.stderr!r}"
    assert not p.stdout
    if py == 2:
        lines = p.stderr.decode(errors="replace").splitlines()
        assert len(lines) == 1 and lines[0].startswith("node: "), lines


@pytest.mark.parametrize("flag, value, status", ISSUE, ids=[f"{f} {v}" for f, v, _ in ISSUE])
def test_issue_55_cases_have_the_stated_verdict(flag, value, status):
    assert python_status(["--check-args", *BASE, flag, value]) == status


@pytest.mark.parametrize("argv", [c[1] for c in HELP], ids=[c[0] for c in HELP])
def test_help_is_the_same_listing_and_exit_0(argv, capsys):
    assert python_status(argv) == 0
    assert capsys.readouterr().out == launch.listing()
    p = cpp_run(argv)
    assert p.returncode == 0 and not p.stderr
    assert p.stdout.decode() == launch.listing("tb-robot")
    for f in dataclasses.fields(NodeArgs):
        assert _flag(f.name) in p.stdout.decode()
    assert launch.CHECK_FLAG in p.stdout.decode()


@pytest.mark.parametrize("argv, status", [
    (["--check-args", *BASE], 0),
    (["--check-args", *BASE, "--time-scale", "1001"], 2),
    (["--help"], 0),
])  # fmt: skip
def test_the_command_line_exits_as_parse_does(argv, status):
    """`python -m node` itself: the same status as NodeArgs.parse, and --check-args runs
    nothing (no body link is opened: there is none)."""
    p = subprocess.run([sys.executable, "-m", "node", *argv], capture_output=True, text=True,
                       timeout=120, cwd=PROJECT_ROOT)  # fmt: skip
    assert p.returncode == status, p.stderr
    assert "Traceback" not in p.stderr


def test_every_field_and_bound_is_exercised():
    """Every NodeArgs field's flag is in some case, each declared bound with a value at it and
    one just beyond it, and the time scale's bounds are common.timescale's."""
    from common import timescale

    given = {a.split("=")[0] for _, argv in CASES for a in argv if a.startswith("--")}
    assert {_flag(f.name) for f in dataclasses.fields(NodeArgs)} <= given
    for f in dataclasses.fields(NodeArgs):
        meta = f.metadata["arg"]
        for bound in ("above", "minimum", "maximum"):
            if meta[bound] is not None:
                at = _beyond({**dict.fromkeys(("above", "minimum", "maximum")), bound: meta[bound]},
                             meta["kind"] is int)  # fmt: skip
                cases = {(argv[-2], argv[-1]) for _, argv in CASES if len(argv) >= 2}
                assert all((_flag(f.name), v) in cases for v in at), (f.name, bound)
    time_scale = {f.name: f for f in dataclasses.fields(NodeArgs)}["time_scale"].metadata["arg"]
    assert (time_scale["minimum"], time_scale["maximum"]) == (timescale.MIN, timescale.MAX)
