"""common.sched: the deadline threads' priority, the switch that turns real time off, and that
the priority neither outlives its block nor passes to children."""

import os
import subprocess
import sys
import threading

import pytest

from common.sched import deadline_priority, raise_priority

needs_root = pytest.mark.skipif(os.geteuid() != 0, reason="real-time priority needs root")


def in_thread(fn):
    out = []
    t = threading.Thread(target=lambda: out.append(fn()))  # only that thread is changed
    t.start()
    t.join()
    return out[0]


def policy_now():
    return os.sched_getscheduler(0) & ~os.SCHED_RESET_ON_FORK


def test_realtime_off_falls_back_to_nice_or_nothing(monkeypatch):
    monkeypatch.setenv("TESTBED_REALTIME", "0")

    def apply():
        return raise_priority(1, 5), policy_now()

    got, policy = in_thread(apply)
    assert policy == os.SCHED_OTHER and got == "nice 5"  # a higher nice needs no root


@needs_root
def test_realtime_as_root(monkeypatch):
    monkeypatch.delenv("TESTBED_REALTIME", raising=False)

    def apply():
        got = raise_priority(1, 5)
        return got, policy_now(), os.sched_getparam(0).sched_priority

    assert in_thread(apply) == ("SCHED_RR 1", os.SCHED_RR, 1)


CHILD_REPORT = "import os; print(os.sched_getscheduler(0), os.getpriority(os.PRIO_PROCESS, 0))"


@needs_root
def test_a_child_started_under_realtime_priority_runs_at_the_default(monkeypatch):
    monkeypatch.delenv("TESTBED_REALTIME", raising=False)

    def apply():
        raise_priority(2, -10)
        return subprocess.run([sys.executable, "-c", CHILD_REPORT], capture_output=True,
                              text=True, check=True).stdout.split()  # fmt: skip

    assert in_thread(apply) == [str(os.SCHED_OTHER), "0"]


@pytest.mark.parametrize("realtime", ["1", "0"])
def test_deadline_priority_restores_the_thread(monkeypatch, realtime):
    monkeypatch.setenv("TESTBED_REALTIME", realtime)

    def apply():
        before = (os.sched_getscheduler(0), os.getpriority(os.PRIO_PROCESS, 0))
        with deadline_priority(1, 3) as got:
            inside = policy_now()
        after = (os.sched_getscheduler(0), os.getpriority(os.PRIO_PROCESS, 0))
        return before, got, inside, after

    before, got, inside, after = in_thread(apply)
    if realtime == "1" and os.geteuid() == 0:
        assert (got, inside) == ("SCHED_RR 1", os.SCHED_RR)
    else:
        assert got == "nice 3" and inside == os.SCHED_OTHER
    if os.geteuid() == 0:  # without root a nice, once raised, cannot be lowered again
        assert after == before
