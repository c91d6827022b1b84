"""Scheduling priority for the threads that keep step deadlines (the world's clock, each
robot's motion control): round-robin real-time priority where allowed, else a nice value.

`TESTBED_REALTIME=0` in the environment turns real-time priority off everywhere."""

from __future__ import annotations

import os


def raise_priority(rt_priority: int, nice: int) -> str:
    """Give the calling thread SCHED_RR `rt_priority`, else nice `nice` (both need root),
    else leave it; returns what it got ("SCHED_RR 2", "nice -10" or "normal")."""
    try:
        if os.environ.get("TESTBED_REALTIME", "1") == "0":
            raise OSError("real-time priority turned off")
        os.sched_setscheduler(0, os.SCHED_RR, os.sched_param(rt_priority))
        return f"SCHED_RR {rt_priority}"
    except (OSError, AttributeError):
        pass
    try:
        os.setpriority(os.PRIO_PROCESS, 0, nice)
        return f"nice {nice}"
    except OSError:
        return "normal"
