"""node.robot's step order: motion control holds a frame until the timer and the planner
finished the previous step's work, for at most three quarters of a step of wall time."""

import threading
import time

from node import body
from node.robot import Robot, RobotConfig
from node.timing import RobotTimings


def _robot(time_scale: float = 10.0) -> Robot:
    cfg = RobotConfig(robot=1, robots=1, shape=(40, 40), timing=RobotTimings(time_scale))
    return Robot(cfg, link=None, flooder=None, goals=None, events=None)


def _frame(step: int, sent: float) -> body.Frame:
    return body.Frame(step, 1.0, 1.0, 0.0, None, sent)


def _at_step(r: Robot, step: int, timer_seen: int) -> None:
    r.s.step = step
    r.timer_seen = timer_seen


def test_a_frame_waits_for_the_plan_asked_at_the_step_before():
    r = _robot(
        time_scale=0.1
    )  # three quarters of a step: 0.75 s of wall time, plenty under any load
    _at_step(r, 3, timer_seen=3)
    r.s.plan_pending, r.s.plan_asked = True, 3

    def install():
        time.sleep(0.01)
        with r.lock:
            r.s.plan_pending = False
            r.caught_up.notify_all()

    t = threading.Thread(target=install)
    t0 = time.monotonic()
    t.start()
    r._keep_step_order(_frame(4, time.monotonic()))
    waited = time.monotonic() - t0
    t.join()
    assert 0.009 <= waited < 0.5
    assert r.order_timeouts == 0
    assert r.lateness["order_wait_ms"].n == 1


def test_a_frame_waits_for_the_timer_to_handle_the_step_before():
    r = _robot(time_scale=0.1)
    _at_step(r, 7, timer_seen=6)

    def timer():
        time.sleep(0.01)
        with r.lock:
            r.timer_seen = 7
            r.caught_up.notify_all()

    t = threading.Thread(target=timer)
    t.start()
    r._keep_step_order(_frame(8, time.monotonic()))
    t.join()
    assert r.order_timeouts == 0
    assert r.lateness["order_wait_ms"].n == 1


def test_nothing_pending_means_no_wait_and_no_record():
    r = _robot()
    _at_step(r, 5, timer_seen=5)
    r.s.plan_pending, r.s.plan_asked = True, 6  # asked at this frame's own step: not owed yet
    r._keep_step_order(_frame(6, time.monotonic()))
    assert r.lateness["order_wait_ms"].n == 0


def test_the_wait_ends_three_quarters_of_a_step_after_the_world_sent_the_frame():
    r = _robot(time_scale=10.0)  # a step is 10 ms of wall time: at most 7.5 ms after the send
    _at_step(r, 3, timer_seen=3)
    r.s.plan_pending, r.s.plan_asked = True, 3  # a planner that never answers
    sent = time.monotonic()
    r._keep_step_order(_frame(4, sent))
    assert time.monotonic() - sent < 0.5
    assert r.order_timeouts == 1
    # recorded in emulated ms: about three quarters of a step (75 ms), however late it woke
    assert r.lateness["order_wait_ms"].max >= 40


def test_a_frame_already_past_its_wait_does_not_wait():
    r = _robot(time_scale=10.0)
    _at_step(r, 3, timer_seen=2)
    t0 = time.monotonic()
    r._keep_step_order(_frame(4, t0 - 1.0))  # sent a second ago
    assert time.monotonic() - t0 < 0.5  # not the wait of a frame sent now
    assert r.order_timeouts == 1


def test_a_plan_held_up_by_the_planners_own_send_is_not_waited_for_nor_judged_late():
    """A plan asked for while the planner waits in a goal send (a middleware that blocks:
    zeromq-reqrep to a dead teammate) would be as late at time scale 1: the frame is not
    held for it, and its age goes to plan_age_blocked_steps, outside the fidelity verdict."""
    r = _robot(time_scale=0.1)  # three quarters of a step: 0.75 s, far above the bound below
    _at_step(r, 3, timer_seen=3)
    r.s.planner_sending = True
    r.request("timer")  # asked at step 3 while the planner sends
    assert r.s.plan_pending and r.s.plan_asked_while_sending
    t0 = time.monotonic()
    r._keep_step_order(_frame(4, time.monotonic()))
    assert time.monotonic() - t0 < 0.2 and r.lateness["order_wait_ms"].n == 0
    # installed later (as _planning does), applied five steps on: apart from the verdict's
    with r.lock:
        r.s.plan_fresh, r.s.plan_fresh_waited = r.s.plan_asked, r.s.plan_asked_while_sending
        r.s.plan_pending = False
        r._plan_applied(9)
    assert r.lateness["plan_age_blocked_steps"].n == 1 and r.lateness["plan_age_steps"].n == 0
    # the same request with the planner idle is waited for, as before
    r2 = _robot(time_scale=10.0)
    _at_step(r2, 3, timer_seen=3)
    r2.request("timer")
    assert not r2.s.plan_asked_while_sending
    r2._keep_step_order(_frame(4, time.monotonic()))
    assert r2.order_timeouts == 1  # nobody installs it: it waited its three quarters
