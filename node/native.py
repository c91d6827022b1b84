"""The C++ robot's entry in a robot namespace: `main(argv)` replaces the process with
build/tb-robot and the same argv (node.launch.NodeArgs' command line, which tb-robot parses
the same way; native/robot). The fork server calls it as it would call node.__main__.main,
so the child keeps its namespace, log, title and parent-death signal, and the runner records
and stops it like any robot. `TESTBED_TB_ROBOT` in the environment names another build of the
same program (the sanitizer tests run build/asan/tb-robot and build/tsan/tb-robot so).
The C++ display is started by node.nativedisplay instead."""

from __future__ import annotations

import os
import sys
from pathlib import Path

from common.paths import PROJECT_ROOT

TB_ROBOT = Path(PROJECT_ROOT) / "build" / "tb-robot"
BINARY_ENV = "TESTBED_TB_ROBOT"
UNBUILT = TB_ROBOT.with_name("tb-robot.unbuilt")  # make setup's line where it could not build it


def unbuilt_reason() -> str | None:
    """Why build/tb-robot is not here: make setup's one line where it could not build it, or
    None. None also where neither the program nor that line is there (setup has not run):
    then what needs the program fails rather than skipping in silence."""
    if TB_ROBOT.is_file():
        return None
    try:
        with open(UNBUILT) as f:
            return f.readline(500).strip() or None
    except OSError:
        return None


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    sys.stdout.flush()
    sys.stderr.flush()
    binary = os.environ.get(BINARY_ENV) or str(TB_ROBOT)
    try:
        os.execv(binary, [binary, *argv])
    except OSError as e:
        sys.stderr.write(f"node: cannot start the C++ robot {binary}: {e.strerror}\n")
        return 2
    return 0  # not reached


if __name__ == "__main__":
    sys.exit(main())
