"""The fidelity verdict (testbed.run.fidelity) and the lateness records it reads (node.lateness)."""

import pytest

from aodv.stats import WORST_KEPT, TimerLateness
from node.lateness import MS_BOUNDS, Lateness
from testbed.files.resultfile import ResultError, RunResult
from testbed.run import fidelity
from testbed.run.fidelity import Measures, Thresholds, measures, verdict
from topology.kernel import nettimers


def robot(plans: int, late: int, timers: int = 0, late_timers: int = 0, age_max: int = 1):
    """A robot's lateness dict as node.robot writes it."""
    p, t = Lateness(), Lateness()
    for i in range(plans):
        p.add(age_max if i < late else 0)
    for i in range(timers):
        t.add(1 if i < late_timers else 0)
    return {"plan_age_steps": p.as_dict(), "plan_timer_steps": t.as_dict()}


def test_lateness_counts_the_maximum_and_the_histogram():
    lat = Lateness()
    for v in (0, 0, 1, 3, 9, -1):
        lat.add(v)
    d = lat.as_dict()
    assert d["n"] == 6 and d["late"] == 3 and d["max"] == 9
    assert d["hist"] == {"<=0": 3, "<=1": 1, "<=2": 0, "<=4": 1, "<=8": 0, ">8": 1}
    assert lat.over(2) == 2


def test_lateness_in_ms_has_its_own_bounds():
    lat = Lateness(MS_BOUNDS)
    lat.add(12.5)
    lat.add(250)
    assert lat.as_dict()["hist"] == {"<=10": 0, "<=25": 1, "<=50": 0, "<=100": 0,
                                     "<=200": 0, ">200": 1}  # fmt: skip
    with pytest.raises(ValueError):
        Lateness((5, 1))


def test_a_run_with_every_plan_on_time_is_faithful():
    v = verdict(measures(0.0, [robot(100, 0, 99, 0)]))
    assert v["ok"] is True and "reason" not in v
    assert v["measures"]["plans"] == 100 and v["measures"]["late_plan_fraction"] == 0.0
    assert v["thresholds"]["late_plan_fraction"] == fidelity.LATE_PLAN_LIMIT


def test_late_plans_over_the_limit_make_a_run_unfaithful_and_say_why():
    v = verdict(measures(0.001, [robot(130, 96, age_max=6)]))
    assert v["ok"] is False
    assert v["reason"] == "96 of 130 plans applied a step or more late (73.8%, limit 1.0%)"
    assert v["measures"]["late_plan_fraction"] == pytest.approx(96 / 130, abs=1e-4)
    assert v["measures"]["plan_age_max_steps"] == 6


def test_plans_are_counted_over_all_robots():
    m = measures(0.0, [robot(100, 1), robot(100, 2), None])
    assert (m.plans, m.late_plans) == (200, 3)
    assert m.late_plan_fraction == 0.015
    assert verdict(m)["ok"] is (fidelity.LATE_PLAN_LIMIT >= 0.015)


def test_each_measure_over_its_threshold_is_a_reason():
    th = Thresholds()
    cases = {
        "deadline": Measures(deadline_miss_fraction=th.deadline_miss_fraction * 2),
        "5 of 10 plan timers fired late (50.0%": Measures(timers=10, late_timers=5),
        "HELLO": Measures(hello_late_max_ms=th.hello_late_max_ms + 1),
        "expiry": Measures(expiry_late_max_ms=th.expiry_late_max_ms + 1),
        "50 of 100 display frames": Measures(display_frames=100, display_late_frames=50),
        "2.0% of step deadlines missed (limit 1.0%)": Measures(deadline_miss_fraction=0.02),
    }
    for words, m in cases.items():
        v = verdict(m)
        assert v["ok"] is False, words
        assert words in v["reason"], (words, v["reason"])
        assert ";" not in v["reason"]  # one reason each


def test_a_measure_at_its_threshold_is_still_faithful():
    th = Thresholds()
    m = Measures(deadline_miss_fraction=th.deadline_miss_fraction,
                 hello_late_max_ms=th.hello_late_max_ms)  # fmt: skip
    assert verdict(m)["ok"] is True


def test_what_was_not_measured_is_not_judged():
    v = verdict(measures(None, [], None, []))
    assert v["ok"] is True
    assert v["measures"]["hello_late_max_ms"] is None


def test_daemons_and_display_are_folded_in():
    daemon = {"hello": {"n": 3, "max": 40.0}, "expiry": {"n": 1, "max": 300.0}}
    display = {"frame_done_ms": Lateness(MS_BOUNDS).as_dict()}
    display["frame_done_ms"]["n"] = 10
    display["frame_done_ms"]["hist"][">200"] = 2
    m = measures(0.0, [], display, [daemon, None, {"hello": {"max": 60.0}}])
    assert (m.hello_late_max_ms, m.expiry_late_max_ms) == (60.0, 300.0)
    assert (m.display_frames, m.display_late_frames) == (10, 2)
    v = verdict(m)
    assert v["ok"] is False and "expiry" in v["reason"] and "display" in v["reason"]


def _daemon(firings: list[tuple[float, float]], scale: float = 10.0) -> dict:
    """A daemon's timer_lateness_ms after HELLOs due at `firings` (monotonic s, emulated ms
    late) at time scale `scale`."""
    timer = TimerLateness()
    for due, ms in firings:
        timer.add(ms, due, due + ms / 1000 / scale)
    return {"hello": timer.as_dict(), "expiry": TimerLateness().as_dict()}


def test_timers_late_outside_the_steps_are_not_judged():
    # Steps from t = 100 to t = 160; a HELLO 900 ms late at the start-up and one 700 ms late
    # while the processes wrote their results, 40 ms at most in between.
    firings = [(95.0, 900.0), (120.0, 40.0), (130.0, 12.0), (161.0, 700.0)]
    daemon = _daemon(firings)
    assert measures(0.0, [], None, [daemon]).hello_late_max_ms == 900.0  # no steps given
    m = measures(0.0, [], None, [daemon], stepping=(100.0, 160.0))
    assert m.hello_late_max_ms == 40.0
    assert verdict(m)["ok"] is True
    # Due before the last step and fired after it: it was late while the robots stepped.
    late_at_end = _daemon([(159.99, 400.0)], scale=1.0)
    assert (
        measures(0.0, [], None, [late_at_end], stepping=(100.0, 160.0)).hello_late_max_ms == 400.0
    )
    # Due before step 0 and still late after it: the same.
    late_at_start = _daemon([(99.9, 300.0)], scale=1.0)
    assert (
        measures(0.0, [], None, [late_at_start], stepping=(100.0, 160.0)).hello_late_max_ms == 300.0
    )


def test_a_daemon_that_kept_only_its_latest_firings_is_judged_on_their_bound():
    # 300 firings, only the 128 most late kept (all of them outside the steps): one not kept may
    # have been inside, at most as late as the least late kept one.
    firings = [(200.0 + i, float(i)) for i in range(300)]
    m = measures(0.0, [], None, [_daemon(firings)], stepping=(0.0, 100.0))
    assert m.hello_late_max_ms == 172.0  # the 128th latest of 0..299
    # An older daemon's file, without times: its maximum over its whole life.
    old = {"hello": {"n": 3, "max": 640.0}}
    assert measures(0.0, [], None, [old], stepping=(0.0, 100.0)).hello_late_max_ms == 640.0


def test_the_worst_firings_are_kept_with_their_times():
    timer = TimerLateness()
    for i in range(WORST_KEPT + 50):
        timer.add(float(i % 97), due=float(i), fired=float(i) + 0.001)
    worst = timer.as_dict()["worst"]
    assert len(worst) == WORST_KEPT
    assert [w[0] for w in worst] == sorted(w[0] for w in worst)  # in the order they were due
    assert min(w[2] for w in worst) == sorted(float(i % 97) for i in range(WORST_KEPT + 50))[50]
    assert max(w[2] for w in worst) == 96.0
    assert all(abs(f - d - 0.001) < 1e-6 for d, f, _ in worst)


CONFIG = {"robots": 2, "comm_range": 5.0, "laser_range": 2.0}


def _result(doc: dict) -> RunResult:
    return RunResult.from_json({"status": "complete", "config": CONFIG, **doc})


def test_a_results_verdict_is_read_as_it_was_written():
    assert _result({"fidelity": {"ok": False}}).faithful is False
    assert _result({"fidelity": {"ok": True}}).faithful is True
    assert _result({}).faithful is None  # written before verdicts
    with pytest.raises(ResultError, match="fidelity"):
        _result({"fidelity": "yes"})


def test_hello_limit_is_half_the_lateness_that_breaks_a_link_in_every_aodv_profile():
    from aodv.params import PROFILES, profile
    from testbed.run.fidelity import HELLO_LATE_LIMIT_MS

    for name in PROFILES:
        p = profile(name)
        breaks_at_ms = (p.allowed_hello_loss - 1) * p.hello_interval_ms
        assert breaks_at_ms / 2 >= HELLO_LATE_LIMIT_MS, name


def test_the_channels_mean_relay_lag_is_judged_against_one_percent_of_a_step():
    from testbed.files.mediumfile import RelayLag
    from testbed.run.fidelity import CHANNEL_LAG_LIMIT_MS, measures, verdict

    assert CHANNEL_LAG_LIMIT_MS == 1.0  # a frame d ms late lands a step late with odds d/100
    on_time = measures(0.0, [], None, [], RelayLag(frames=900, mean_ms=0.45, max_ms=30.0))
    assert (on_time.channel_frames, on_time.channel_lag_mean_ms) == (900, 0.45)
    assert verdict(on_time)["ok"] is True
    behind = verdict(measures(0.0, [], None, [], RelayLag(frames=900, mean_ms=2.03)))
    assert behind["ok"] is False
    assert behind["reason"] == (
        "2.03 ms: the 802.11 channel relayed frames that late on average (limit 1)"
    )
    assert behind["measures"]["channel_lag_mean_ms"] == 2.03


def test_a_run_without_the_channel_or_its_mean_is_not_judged_on_it():
    # A malformed relay_lag is mediumfile's ResultError (tests/unit/test_medium_file.py).
    from testbed.files.mediumfile import RelayLag
    from testbed.run.fidelity import measures, verdict

    for channel in (None, RelayLag(frames=3, mean_ms=None)):
        m = measures(0.0, [], None, [], channel)
        assert (m.channel_frames, m.channel_lag_mean_ms) == (0, None)
        assert verdict(m)["ok"] is True


# -- the network's verdict: TCP's timers in emulated time (topology.kernel.nettimers) --------------

JIFFY = 4000
KERNEL_618 = {"net.ipv4.tcp_rto_min_us": 200_000, "net.ipv4.tcp_rto_max_ms": 120_000}
KERNEL_68 = {"net.ipv4.neigh.wlan0.retrans_time_ms": 1000}  # no tcp_rto_min_us


def test_the_network_is_in_emulated_time_at_time_scale_1_whatever_the_kernel():
    record = nettimers.plan(1, KERNEL_68, JIFFY).to_dict()
    assert fidelity.network_verdict(record, 1.0) == {"ok": True}
    assert fidelity.network_verdict(None, 1.0) == {"ok": True}


def test_a_dilated_run_with_tcps_timer_dilated_is_ok():
    record = nettimers.plan(10, KERNEL_618, JIFFY, "6.18").to_dict()
    assert fidelity.network_verdict(record, 10.0) == {"ok": True}


def test_a_dilated_run_whose_kernel_has_no_rto_floor_says_so():
    record = nettimers.plan(6, KERNEL_68, JIFFY, "6.8.0").to_dict()
    v = fidelity.network_verdict(record, 6.0)
    assert v["ok"] is False
    assert v["reason"] == (
        "TCP's retransmission timeout is not dilated at time scale 6: this kernel has no "
        "net.ipv4.tcp_rto_min_us (Linux 6.11 and later)"
    )


def test_a_time_scale_past_the_kernels_jiffy_says_so():
    v = fidelity.network_verdict(nettimers.plan(30, KERNEL_618, JIFFY).to_dict(), 30.0)
    assert v["ok"] is False and "the kernel's floor of 4000 us (one jiffy" in v["reason"]


def test_a_dilated_run_without_a_record_or_with_a_bad_one_is_not_in_emulated_time():
    assert fidelity.network_verdict(None, 6.0)["ok"] is False
    bad = fidelity.network_verdict({"time_scale": 6}, 6.0)
    assert bad["ok"] is False and "unreadable" in bad["reason"]


def test_which_results_ran_tcp_in_emulated_time():
    def result(scale, network=None):
        out = {"time_scale_requested": scale, "fidelity": {"ok": True}}
        if network is not None:
            out["fidelity"]["network"] = network
        return _result(out)

    assert result(1).tcp_in_emulated_time is True
    assert result(6, {"ok": True}).tcp_in_emulated_time is True
    assert result(6, {"ok": False, "reason": "x"}).tcp_in_emulated_time is False
    assert result(6).tcp_in_emulated_time is False  # made before TCP was dilated
    assert _result({"config": dict(CONFIG, time_scale=1)}).tcp_in_emulated_time is True
    assert _result({}).tcp_in_emulated_time is True  # no time scale said: the wall clock's


def test_a_done_that_reached_the_world_late_is_counted_by_robot_not_judged():
    """The robot's finish is its message's step: a late "done" changes no exploration time,
    only how long the world ran, so it is recorded and the verdict does not count it."""
    m = measures(0.0, [], None, [], done_late=[0, 2, 1, 0])
    assert (m.late_dones, m.done_late_max_steps) == (2, 2)
    v = verdict(m)
    assert v["ok"] is True and v["measures"]["late_dones"] == 2
    assert "late_dones" not in v["thresholds"]
