"""node.sched: the deadline threads' priority, and the switch that turns real time off."""

import os
import threading

import pytest

from node.sched import raise_priority


def in_thread(fn):
    out = []
    t = threading.Thread(target=lambda: out.append(fn()))  # only that thread is changed
    t.start()
    t.join()
    return out[0]


def test_realtime_off_falls_back_to_nice_or_nothing(monkeypatch):
    monkeypatch.setenv("TESTBED_REALTIME", "0")

    def apply():
        return raise_priority(1, 5), os.sched_getscheduler(0)

    got, policy = in_thread(apply)
    assert policy == os.SCHED_OTHER and got == "nice 5"  # a higher nice needs no root


@pytest.mark.skipif(os.geteuid() != 0, reason="real-time priority needs root")
def test_realtime_as_root(monkeypatch):
    monkeypatch.delenv("TESTBED_REALTIME", raising=False)

    def apply():
        got = raise_priority(1, 5)
        return got, os.sched_getscheduler(0), os.sched_getparam(0).sched_priority

    assert in_thread(apply) == ("SCHED_RR 1", os.SCHED_RR, 1)
