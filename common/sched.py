"""Scheduling priority for the threads that keep deadlines: round-robin real-time priority
where allowed, else a nice value.

Who gets it (docs/architecture.md, "The process tree and its priorities"): the world's step
loop at 2, the clock; at 1 whatever has a deadline the fidelity verdict checks, each robot's
motion control, planner and timer, the display's frame loop and each AODV daemon's loop (its
HELLO and expiry timers). The bulk work stays at normal priority and takes what is left: map
merges and the inboxes, the middleware's threads, the captures, the fork servers.

The priority is the calling thread's alone and never leaks: real-time priority is set with
SCHED_RESET_ON_FORK, so a process forked while it holds (a fork server, a routing daemon)
starts at the default policy and nice, and `deadline_priority` puts the thread back as it was
when its block ends (a process that runs several runs in turn, as the benchmark does, would
otherwise start the next run's fork server, and so every robot, at the world's priority).

`TESTBED_REALTIME=0` in the environment turns real-time priority off everywhere."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator

from common import envswitch

# (SCHED_RR priority, nice where real-time priority is refused)
CLOCK_PRIORITY = (2, -10)  # the world's step loop: the clock everything is measured against
DEADLINE_PRIORITY = (1, -5)  # every part with a deadline the fidelity verdict checks


def raise_priority(rt_priority: int, nice: int) -> str:
    """Give the calling thread SCHED_RR `rt_priority` (reset in its children), else nice
    `nice` (both need root), else leave it; returns what it got ("SCHED_RR 2", "nice -10" or
    "normal")."""
    try:
        if envswitch.value("TESTBED_REALTIME") == "0":
            raise OSError("real-time priority turned off")
        policy = os.SCHED_RR | os.SCHED_RESET_ON_FORK
        os.sched_setscheduler(0, policy, os.sched_param(rt_priority))
        return f"SCHED_RR {rt_priority}"
    except (OSError, AttributeError):
        pass
    try:
        os.setpriority(os.PRIO_PROCESS, 0, nice)
        return f"nice {nice}"
    except OSError:
        return "normal"


@contextlib.contextmanager
def deadline_priority(rt_priority: int, nice: int) -> Iterator[str]:
    """`raise_priority` for the block, yielding what it got; the thread's policy, real-time
    priority and nice are restored afterwards (as root; without root there was no real-time
    priority to take back, and a nice once raised stays)."""
    policy = os.sched_getscheduler(0)
    param = os.sched_getparam(0)
    niceness = os.getpriority(os.PRIO_PROCESS, 0)
    try:
        yield raise_priority(rt_priority, nice)
    finally:
        with contextlib.suppress(OSError):
            os.sched_setscheduler(0, policy, param)
        with contextlib.suppress(OSError):
            os.setpriority(os.PRIO_PROCESS, 0, niceness)
