"""Which robot program a run starts: the C++ robot (build/tb-robot, native/robot) or the
Python robot (`python -m node`), and why (result.json's `robot` and `robot_reason`).

`--robot auto` (the default) takes the C++ robot wherever it was built and carries the run's
options: its middlewares (`tb-robot --middlewares`: nanomsg, and ZeroMQ where make setup
found libzmq3-dev) with flooded maps. Elsewhere the Python robot runs and the reason says what
was missing. `--robot cpp` insists (a run it cannot carry is refused before it starts);
`--robot python` asks for the reference. The display runs the robots' program (a mixed
team's, a test's, has the Python display).
"""

from __future__ import annotations

import functools
import os
import subprocess

from node.native import BINARY_ENV, TB_ROBOT, unbuilt_reason
from testbed.files.runconfig import ROBOT_CHOICES as CHOICES

CPP_MAPS = ("flood",)


@functools.cache
def _carried(binary: str) -> tuple[str, ...]:
    try:
        p = subprocess.run([binary, "--middlewares"], capture_output=True, text=True,
                           timeout=10)  # fmt: skip
    except (OSError, subprocess.TimeoutExpired):
        return ()
    return tuple(p.stdout.split()) if p.returncode == 0 else ()


def carried_middlewares() -> tuple[str, ...]:
    """The middlewares the built C++ robot carries (asked once per process); () if none."""
    return _carried(os.environ.get(BINARY_ENV) or str(TB_ROBOT))


def cpp_refusal(
    middleware: str, maps: str, built: bool | None = None, carries: tuple[str, ...] | None = None
) -> str:
    """Why the C++ robot cannot run with these options ("" when it can)."""
    if built is None:
        built = TB_ROBOT.is_file()
    if not built:
        return unbuilt_reason() or (
            f"{TB_ROBOT.name} not built (make setup builds it where g++ and libnng-dev are)"
        )
    if carries is None:
        carries = carried_middlewares()
    if middleware not in carries:
        return (
            f"it carries {' and '.join(carries) or 'no middleware'}, not --middleware {middleware}"
        )
    if maps not in CPP_MAPS:
        return f"it floods maps, not --maps {maps}"
    return ""


def choose(
    robot: str,
    middleware: str,
    maps: str,
    built: bool | None = None,
    carries: tuple[str, ...] | None = None,
) -> tuple[str, str]:
    """(the robot program, "cpp" or "python"; the reason) for a run's options. ValueError
    for `--robot cpp` where the C++ robot cannot run."""
    if robot == "python":
        return "python", "python: asked for"
    why = cpp_refusal(middleware, maps, built, carries)
    if robot == "cpp":
        if why:
            raise ValueError(f"--robot cpp: the C++ robot cannot run this: {why}")
        return "cpp", "cpp: asked for"
    if robot != "auto":
        raise ValueError(f"--robot {robot!r}: one of {', '.join(CHOICES)}")
    if why:
        return "python", f"auto: the C++ robot cannot run this: {why}"
    return "cpp", f"auto: built and carries {middleware}"
