"""A program for the fork server's test: `main([OUT, STATUS])` writes which network
namespace it runs in, its argv, and its SIGINT handler and parent-death signal to OUT, and
returns STATUS (or sleeps when it is 'sleep')."""

import ctypes
import os
import signal
import sys
import time

_PR_GET_PDEATHSIG = 2


def main(argv: list[str]) -> int:
    out, status = argv
    with open(out, "w") as f:
        f.write(f"{os.stat('/proc/self/ns/net').st_ino} {os.getsid(0) == os.getpid()}\n")
        f.write(" ".join(sys.argv) + "\n")
        pdeathsig = ctypes.c_int(0)
        ctypes.CDLL(None).prctl(_PR_GET_PDEATHSIG, ctypes.byref(pdeathsig), 0, 0, 0)
        default_int = signal.getsignal(signal.SIGINT) is signal.default_int_handler
        f.write(f"{default_int} {pdeathsig.value}\n")
    print("probe ran", flush=True)
    if status == "sleep":
        time.sleep(60)
    return int(status) if status != "sleep" else 0
