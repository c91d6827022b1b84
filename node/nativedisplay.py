"""The C++ display's entry in its namespace: `main(argv)` runs `tb-robot --role display`
(native/robot/display.cc) with the same argv as a child, for the part of the display that
keeps step with the robots; passes it SIGTERM; and once it has exited draws what it kept
(node.displayreplay) with the OpenCV the fork server already imported. The fork server calls
it as it calls node.__main__.main for the Python display; `TESTBED_TB_ROBOT` names another
build, as for node.native."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

from node import displayreplay
from node.events import EventLog
from node.launch import NodeArgs
from node.native import BINARY_ENV, TB_ROBOT


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    binary = os.environ.get(BINARY_ENV) or str(TB_ROBOT)
    args = NodeArgs.parse(argv)  # bad arguments: one line, exit 2
    sys.stdout.flush()
    sys.stderr.flush()
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
