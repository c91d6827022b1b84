"""The C++ robot's entry in a robot namespace: `main(argv)` replaces the process with
build/tb-robot and the same argv (node.launch.NodeArgs' command line, which tb-robot parses
the same way; native/robot). The fork server calls it as it would call node.__main__.main,
so the child keeps its namespace, log, title and parent-death signal, and the runner records
and stops it like any robot. `TESTBED_TB_ROBOT` in the environment names another build of the
same program (the sanitizer tests run build/asan/tb-robot and build/tsan/tb-robot so).

The display (`--role display`) is not replaced: tb-robot runs its part that keeps step with
the robots as a child, this process passes it SIGTERM, and once it has exited draws what it
kept (node.displayreplay) with the OpenCV the fork server already imported."""

from __future__ import annotations

import os
import signal
import subprocess
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
    if _role(argv) == "display":
        return _display(binary, argv)
    try:
        os.execv(binary, [binary, *argv])
    except OSError as e:
        sys.stderr.write(f"node: cannot start the C++ robot {binary}: {e.strerror}\n")
        return 2
    return 0  # not reached


def _role(argv: list[str]) -> str:
    """The --role an argv asks for (node.launch.NodeArgs': "robot" unless it says)."""
    role = "robot"
    for i, a in enumerate(argv):
        if a == "--role" and i + 1 < len(argv):
            role = argv[i + 1]
        elif a.startswith("--role="):
            role = a.split("=", 1)[1]
    return role


def _display(binary: str, argv: list[str]) -> int:
    """The C++ display's part while the robots step, as a child; then its pictures here."""
    from node import displayreplay
    from node.events import EventLog
    from node.launch import NodeArgs

    args = NodeArgs.parse(argv)  # bad arguments: one line, exit 2
    try:
        child = subprocess.Popen([binary, *argv])
    except OSError as e:
        sys.stderr.write(f"node: cannot start the C++ display {binary}: {e.strerror}\n")
        return 2
    signal.signal(signal.SIGTERM, lambda signum, frame: child.send_signal(signum))
    status = child.wait()
    if status != 0:  # it said why (or was killed): nothing to draw
        return status if status > 0 else 3
    assert args.out_dir is not None  # the C++ display refuses to start without one
    events = EventLog(args.events)
    try:
        displayreplay.finish(args.out_dir, args.map_size, args.cell, events)
    except ValueError as e:
        sys.stderr.write(f"node: r{args.robot}: {e}\n")
        return 3
    finally:
        events.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
