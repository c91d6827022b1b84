"""Faults a run makes on purpose: a robot stopped (`--kill`) and a radio out of range
(`--isolate`). A stopped robot is no crash: the others decide the run's status, and the
averages over robots leave it out; an isolated robot has no link, whatever the positions."""

import pytest

from testbed.files import isolation
from testbed.files.isolation import Outage
from testbed.run.record import RobotRecord, RunRecord
from testbed.run.stepclock import ClockSummary
from testbed.run.steploop import final_status, over
from topology.network import Network
from topology.spec import NetworkSpec


def _robots(finish: list[int | None]) -> list[RobotRecord]:
    out = []
    for k, s in enumerate(finish, start=1):
        r = RobotRecord(k)
        if s is not None:
            r.finished(s)
        out.append(r)
    return out


def _record(robots: list[RobotRecord], steps: int) -> RunRecord:
    clock = ClockSummary(steps, len(robots), 1.0, 1.0, 0, 0)
    return RunRecord("/x", {}, 1.0, "complete", "", None, tuple(r.outcome() for r in robots),
                     clock, {}, {}, None, 0.0)  # fmt: skip


def test_a_stopped_robot_is_left_out_of_the_mean_and_counted_as_left_out():
    r1, r2, r3 = _robots([1072, None, 1081])
    r2.stop(150)
    rec = _record([r1, r2, r3], steps=1082)
    # r2 would have counted 1082 (the last step) as if it had explored to the end
    assert rec.mean_finish_step == pytest.approx((1072 + 1081) / 2)
    assert [r.k for r in rec.counted_robots] == [1, 3]
    assert rec.survivors_finished and rec.last_finish_step == 1081
    # a survivor that did not finish still counts the last step, and the survivors did not
    r3b = _robots([None])[0]
    r3b.k = 3
    rec = _record([r1, r2, r3b], steps=2000)
    assert rec.mean_finish_step == pytest.approx((1072 + 2000) / 2)
    assert not rec.survivors_finished
    # nobody counted: no mean
    r1.stop(10), r3.stop(10)
    rec = _record([r1, r2, r3], steps=20)
    assert rec.mean_finish_step is None and rec.counted_robots == ()
    assert not rec.survivors_finished


def test_a_crashed_robot_still_counts_and_is_no_survivor():
    r1, r2 = _robots([100, None])
    r2.died(50, -9)
    rec = _record([r1, r2], steps=300)
    assert rec.mean_finish_step == pytest.approx(200.0)  # as before: the last step
    assert rec.survivors_finished  # r1, the only one left, finished


def test_the_robots_not_stopped_decide_the_status():
    r1, r2, r3 = _robots([None, None, None])
    r2.stop(150)
    assert over([r1, r2, r3], 200, 4000) is None  # r1 and r3 still exploring
    r1.finished(900)
    r3.finished(1000)
    status = over([r1, r2, r3], 1001, 4000)
    assert status == (
        "complete",
        "the robots not stopped finished by step 1000; r2 stopped at step 150",
    )
    assert final_status(status, [r1, r2, r3]) == status  # a stop is no crash
    # a robot that dies unasked is a crash, stopped robots or not
    r3.died(1000, 1)
    assert final_status(status, [r1, r2, r3])[0] == "robot_crashed"


def test_without_stops_the_status_is_as_before():
    r1, r2 = _robots([10, 12])
    assert over([r1, r2], 13, 100) == ("complete", "all robots finished by step 12")
    r1, r2 = _robots([10, None])
    assert over([r1, r2], 100, 100) == ("step_cap", "the step cap (100) was reached")
    r2.died(40, -9)
    assert over([r1, r2], 41, 100) == ("complete", "all robots finished by step 10")
    r1.died(42, -9)
    assert over([r1, r2], 43, 100) == ("robot_crashed", "every robot process died")


def test_every_robot_stopped_is_its_own_status():
    r1, r2 = _robots([None, None])
    r1.stop(5)
    r2.stop(5)
    assert over([r1, r2], 6, 100) == ("stopped", "every robot was stopped (--kill)")
    r1, r2 = _robots([None, None])
    r1.stop(5)
    r2.died(7, 1)
    assert over([r1, r2], 8, 100)[0] == "robot_crashed"


def test_a_stopped_robot_misses_no_deadline():
    r = RobotRecord(1)
    r.answered(4)
    r.stop(5)
    assert r.gone and not r.crashed and not r.missed_deadline(6)


def test_outage_windows():
    assert Outage.parse("r3:200:100") == Outage(3, 200, 100) == Outage.parse("3:200:100")
    assert Outage(3, 200, 100).text() == "r3:200:100"
    for bad in ("r3:200", "r3:0:10", "r3:10:0", "x:1:1", "r3:1:1:1"):
        with pytest.raises(ValueError, match="--isolate"):
            Outage.parse(bad)
    windows = (Outage(3, 200, 100), Outage(1, 250, 10))
    assert isolation.isolated_at(windows, 199) == frozenset()
    assert isolation.isolated_at(windows, 200) == {3}
    assert isolation.isolated_at(windows, 255) == {1, 3}
    assert isolation.isolated_at(windows, 299) == {3}
    assert isolation.isolated_at(windows, 300) == frozenset()  # back at start + steps
    assert [i.to_dict() for i in isolation.record(windows, 1000)] == [
        {"robot": "r3", "from_step": 200, "back_step": 300},
        {"robot": "r1", "from_step": 250, "back_step": 260},
    ]
    # the run ended while r3 was out, and before r1's window began
    assert [i.to_dict() for i in isolation.record(windows, 240)] == [
        {"robot": "r3", "from_step": 200, "back_step": None}
    ]


def test_an_isolated_robot_has_no_link_whatever_the_positions():
    # four robots within 1 m of each other: every pair linked at 5 m
    spec = NetworkSpec(name="fal1", positions=((0, 0), (1, 0), (0, 1), (1, 1)), comm_range=5.0)
    net = Network(spec)
    assert set(net.wanted()) == {(1, 2), (1, 3), (1, 4), (2, 3), (2, 4), (3, 4)}
    net.isolated = frozenset({3})
    assert set(net.wanted()) == {(1, 2), (1, 4), (2, 4)}
    net.isolated = frozenset({3, 4})
    assert set(net.wanted()) == {(1, 2)}
