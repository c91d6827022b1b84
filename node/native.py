"""The C++ robot's entry in a robot namespace: `main(argv)` replaces the process with
build/tb-robot and the same argv (node.launch.NodeArgs' command line, which tb-robot parses
the same way; native/robot). The fork server calls it as it would call node.__main__.main,
so the child keeps its namespace, log, title and parent-death signal, and the runner records
and stops it like any robot."""

from __future__ import annotations

import os
import sys
from pathlib import Path

TB_ROBOT = Path(__file__).resolve().parent.parent / "build" / "tb-robot"


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    sys.stdout.flush()
    sys.stderr.flush()
    try:
        os.execv(TB_ROBOT, [str(TB_ROBOT), *argv])
    except OSError as e:
        sys.stderr.write(f"node: cannot start the C++ robot {TB_ROBOT}: {e.strerror}\n")
        return 2
    return 0  # not reached


if __name__ == "__main__":
    sys.exit(main())
