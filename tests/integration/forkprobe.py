"""A program for the fork server's test: `main([OUT, STATUS])` writes which network
namespace it runs in and its argv to OUT, and returns STATUS (or sleeps when it is 'sleep')."""

import os
import sys
import time


def main(argv: list[str]) -> int:
    out, status = argv
    with open(out, "w") as f:
        f.write(f"{os.stat('/proc/self/ns/net').st_ino} {os.getsid(0) == os.getpid()}\n")
        f.write(" ".join(sys.argv) + "\n")
    print("probe ran", flush=True)
    if status == "sleep":
        time.sleep(60)
    return int(status) if status != "sleep" else 0
