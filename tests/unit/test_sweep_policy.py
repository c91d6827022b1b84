"""The sweep's rules for late runs (testbed.sweep.policy), one test per rule, pure."""

import copy
from dataclasses import replace

import pytest

from testbed.sweep.policy import (
    CLEAN_RUNS_TO_SPEED_UP,
    MIN_SCALE_FACTOR,
    SLOWDOWN,
    Decision,
    Outcome,
    State,
    decide,
)


def outcome(miss, ours=None, **kw):
    return Outcome(robots=kw.pop("robots", 5), miss=miss,
                   miss_outside_stalls=miss if ours is None else ours, **kw)  # fmt: skip


def test_rule1_a_run_within_the_limit_changes_nothing():
    state = State(jobs=1)
    d = decide(outcome(0.009), state)
    assert d.state == state and not d.redo and d.backoffs == () and d.words == ""


def test_rule1_a_run_that_reported_nothing_changes_nothing():
    d = decide(outcome(None), State(jobs=1))
    assert d == decide(outcome(0.0), State(jobs=1))


def test_rule2_misses_in_host_stalls_keep_the_scale_and_redo_only_a_bad_run():
    state = State(jobs=1)
    bad = decide(outcome(0.08, ours=0.004), state)
    assert bad.state == state and bad.redo
    assert bad.backoffs == ({"deadline_miss_fraction": 0.08, "in_host_stalls": True},)
    assert bad.words == (", missed 8.0% of step deadlines (7.6% in host stalls); the host's "
                         "stalls, time scale kept, redoing it")  # fmt: skip
    assert not decide(outcome(0.08, ours=0.004, attempts=3), state).redo  # 3 attempts at most
    mild = decide(outcome(0.03, ours=0.004), state)
    assert mild.state == state and not mild.redo and mild.backoffs == ()
    assert mild.words == ", missed 3.0% of step deadlines (2.6% in host stalls)"


def test_rule3_a_run_late_beside_a_tail_gives_up_the_overlap_first():
    """Late while another run's tail overlapped it: its team size overlaps tails no more,
    nothing else changes (the limits, the jobs, the time scale), and the run is redone once;
    an unfaithful one the same. Once its team size waits for tails, the other rules act."""
    state = State(jobs=2, cpu_limit=1.6, no_overlap=frozenset({3}))
    for late in (outcome(0.03, overlapped=True, shared=True, jobs_at_start=2),
                 outcome(0.0, overlapped=True, faithful=False)):  # fmt: skip
        d = decide(late, state)
        assert d.state == replace(state, no_overlap=frozenset({3, 5}), overlap_clean={5: 0},
                                  overlap_strikes={5: 1}) and d.redo  # fmt: skip
        assert d.backoffs[0]["overlap"] is False and d.backoffs[0]["robots"] == 5
        assert "teams of 5 no longer start during another run's teardown, redoing it" in d.words
        assert not decide(replace(late, attempts=2), state).redo
    off = decide(outcome(0.03, overlapped=True, shared=True, robots=3), state)
    assert "cpu_limit" in off.backoffs[0] and "overlap" not in off.backoffs[0]
    alone = decide(outcome(0.03), state)
    assert alone.state.no_overlap == {3} and "time_scale_factor" in alone.backoffs[0]


def test_rule3a_a_run_late_beside_a_prestart_gives_up_prestart_beside_its_team_size():
    """Late (or unfaithful) while the next run pre-started beside its steps: no run is
    pre-started beside its team size any more, nothing else changes, and the run is redone
    once. Rule 3 goes first for a run that had both; once pre-start is off for its team
    size, the other rules act."""
    state = State(jobs=1, load_limit=40.0, no_prestart=frozenset({3}))
    for late in (outcome(0.03, prestarted_beside=True, shared=True),
                 outcome(0.0, prestarted_beside=True, faithful=False)):  # fmt: skip
        d = decide(late, state)
        assert d.state == replace(state, no_prestart=frozenset({3, 5}), prestart_clean={5: 0},
                                  prestart_strikes={5: 1}) and d.redo  # fmt: skip
        assert d.backoffs[0]["prestart"] is False and d.backoffs[0]["robots"] == 5
        assert "no run is pre-started beside teams of 5 any more, redoing it" in d.words
        assert not decide(replace(late, attempts=2), state).redo
    both = decide(outcome(0.03, overlapped=True, prestarted_beside=True), state)
    assert both.state.no_overlap == {5} and both.state.no_prestart == {3}
    off = decide(outcome(0.03, prestarted_beside=True, shared=True, robots=3), state)
    assert "load_limit" in off.backoffs[0] and "prestart" not in off.backoffs[0]
    alone = decide(outcome(0.03), state)
    assert alone.state.no_prestart == {3} and "time_scale_factor" in alone.backoffs[0]


def test_rule9a_clean_runs_take_prestart_up_again_ever_more_slowly():
    """After rule 3a, CLEAN_RUNS_TO_SPEED_UP clean runs of the team size bring pre-start
    beside it back (recorded, said); each later firing of rule 3a doubles the clean runs it
    takes. A late or unfaithful run, or another team size's, does not count."""
    state = State(jobs=1)
    for strikes in (1, 2, 3):
        state = decide(outcome(0.03, prestarted_beside=True), state).state
        assert state.no_prestart == {5} and state.prestart_strikes == {5: strikes}
        needed = CLEAN_RUNS_TO_SPEED_UP * 2 ** (strikes - 1)
        for _ in range(needed - 1):
            state = decide(outcome(0.0, robots=4), state).state  # another team size
            d = decide(outcome(0.0), state)
            assert d.state.no_prestart == {5} and d.backoffs == ()
            state = d.state
        unfaithful = decide(outcome(0.0, faithful=False), state)
        assert unfaithful.state.prestart_clean == state.prestart_clean
        assert decide(outcome(0.02), state).state.prestart_clean == state.prestart_clean
        back = decide(outcome(0.001), state)
        assert back.state.no_prestart == frozenset() and back.state.prestart_clean == {5: 0}
        assert back.backoffs == ({"robots": 5, "prestart": True},)
        assert back.words == "; runs are pre-started beside teams of 5 again"
        state = back.state


def test_rule9_clean_runs_take_the_overlap_up_again_ever_more_slowly():
    """After rule 3, CLEAN_RUNS_TO_SPEED_UP clean runs of the team size bring the overlap
    back (recorded, said); each later firing of rule 3 doubles the clean runs it takes. A late
    or unfaithful run, or another team size's, does not count."""
    state = State(jobs=1)
    for strikes in (1, 2, 3):
        late = decide(outcome(0.03, overlapped=True), state)
        state = late.state
        assert state.no_overlap == {5} and state.overlap_strikes == {5: strikes}
        needed = CLEAN_RUNS_TO_SPEED_UP * 2 ** (strikes - 1)
        for _ in range(needed - 1):
            state = decide(outcome(0.0, robots=4), state).state  # another team size
            d = decide(outcome(0.0), state)
            assert d.state.no_overlap == {5} and d.backoffs == ()
            state = d.state
        unfaithful = decide(outcome(0.0, faithful=False, overlapped=False), state)
        assert unfaithful.state.overlap_clean == state.overlap_clean
        back = decide(outcome(0.001), state)
        assert back.state.no_overlap == frozenset() and back.state.overlap_clean == {5: 0}
        assert back.backoffs == ({"robots": 5, "overlap": True},)
        assert back.words == "; teams of 5 start during another run's teardown again"
        state = back.state


def test_rule4_a_shared_run_under_a_load_limit_lowers_it_to_80_percent_of_what_it_saw():
    d = decide(outcome(0.02, shared=True, load_seen=40.0), State(jobs=4, load_limit=50.0))
    assert d.state.load_limit == 32.0 and d.state.jobs == 4 and d.redo
    assert d.backoffs == ({"deadline_miss_fraction": 0.02, "load_limit": 32.0},)
    assert d.words.endswith("; load limit down to 32, redoing it")
    assert not decide(outcome(0.02, shared=True, load_seen=40.0, attempts=2),
                      State(jobs=4, load_limit=50.0)).redo  # fmt: skip
    # Never up: a limit already below 80% of the load seen stays.
    assert decide(outcome(0.02, shared=True, load_seen=40.0),
                  State(jobs=4, load_limit=20.0)).state.load_limit == 20.0  # fmt: skip


def test_rule4_a_shared_unfaithful_run_under_a_cpu_limit_lowers_it_to_80_percent_of_what_it_saw():
    state = State(jobs=2, cpu_limit=1.8)
    d = decide(outcome(0.0, faithful=False, shared=True, cpu_seen=1.5, jobs_at_start=2), state)
    assert d.state.cpu_limit == 1.2 and d.state.jobs == 2 and d.redo
    assert d.state.scale_factors == {} and d.state.load_limit is None
    assert d.backoffs == ({"deadline_miss_fraction": 0.0, "cpu_limit": 1.2, "faithful": False},)
    assert d.words.endswith("; cpu limit down to 1.2 cores, redoing it")
    assert not decide(outcome(0.0, faithful=False, shared=True, cpu_seen=1.5, attempts=2),
                      state).redo  # fmt: skip
    # Late rather than unfaithful: the same; and never up.
    assert decide(outcome(0.02, shared=True, cpu_seen=1.5), state).state.cpu_limit == 1.2
    assert decide(outcome(0.02, shared=True, cpu_seen=1.5),
                  State(jobs=2, cpu_limit=0.9)).state.cpu_limit == 0.9  # fmt: skip


def test_rule4_with_both_limits_lowers_each_below_what_the_run_saw():
    d = decide(outcome(0.02, shared=True, load_seen=40.0, cpu_seen=1.5),
               State(jobs=2, load_limit=50.0, cpu_limit=1.8))  # fmt: skip
    assert (d.state.load_limit, d.state.cpu_limit) == (32.0, 1.2) and d.redo
    assert d.words.endswith("; load limit down to 32, cpu limit down to 1.2 cores, redoing it")


def test_a_run_alone_under_a_cpu_limit_slows_its_team_size_down_as_rule5_says():
    """Alone, the limit is not to blame (rule 6), even when two runs were allowed at its
    start; rule 5's one job fewer is for sweeps without limits."""
    state = State(jobs=2, cpu_limit=1.8)
    d = decide(outcome(0.0, faithful=False, cpu_seen=0.9, jobs_at_start=2), state)
    assert d.state.cpu_limit == 1.8 and d.state.jobs == 2
    assert d.state.scale_factors == {5: SLOWDOWN} and d.redo
    assert d.backoffs == decide(outcome(0.0, faithful=False), State(jobs=1)).backoffs


def test_rule5_without_a_load_limit_one_run_fewer_at_a_time():
    d = decide(outcome(0.02, shared=True, jobs_at_start=3), State(jobs=3))
    assert d.state.jobs == 2 and d.redo
    assert d.backoffs == ({"deadline_miss_fraction": 0.02, "jobs": 2},)
    assert d.words.endswith("; concurrency down to 2, redoing it")
    # From the concurrency it started under, if that was lower than today's.
    assert decide(outcome(0.02, jobs_at_start=2), State(jobs=4)).state.jobs == 1


def test_rule6_alone_and_late_slows_its_team_size_down_and_redoes_only_a_bad_run():
    state = State(jobs=1, scale_factors={3: 0.5})
    d = decide(outcome(0.02, robots=5), state)
    assert d.state.scale_factors == {3: 0.5, 5: SLOWDOWN} and d.state.clean_runs == {5: 0}
    assert not d.redo  # 2% is kept: its result records what it missed
    assert d.backoffs == (
        {"deadline_miss_fraction": 0.02, "robots": 5, "time_scale_factor": SLOWDOWN},
    )
    assert d.words.endswith("; time scales of teams of 5 down to 85% of the file's")
    bad = decide(outcome(0.06, robots=5), state)
    assert bad.redo and bad.words.endswith(", redoing it")
    assert not decide(outcome(0.06, robots=5, attempts=3), state).redo


def test_rule6_stops_at_the_floor():
    near = State(jobs=1, scale_factors={5: 0.27})
    assert decide(outcome(0.02), near).state.scale_factors[5] == MIN_SCALE_FACTOR
    floor = State(jobs=1, scale_factors={5: MIN_SCALE_FACTOR})
    d = decide(outcome(0.06), floor)
    assert d.state == floor and not d.redo and d.backoffs == ()


def test_rule8_clean_runs_speed_a_slowed_size_up_a_notch_never_past_the_file():
    state = State(jobs=1, scale_factors={5: SLOWDOWN})
    for i in range(1, CLEAN_RUNS_TO_SPEED_UP):
        d = decide(outcome(0.004), state)
        assert d.state.clean_runs == {5: i} and d.state.scale_factors == {5: SLOWDOWN}
        assert d.backoffs == () and d.words == ""
        state = d.state
    d = decide(outcome(0.004), state)
    assert d.state.scale_factors == {5: pytest.approx(1.0)} and d.state.clean_runs == {5: 0}
    assert d.backoffs == ({"robots": 5, "time_scale_factor": pytest.approx(1.0)},)
    assert d.words == "; time scales of teams of 5 up to 100%"
    # A size at the file's scale has nothing to speed up; a run over CLEAN_MISS is not clean.
    assert decide(outcome(0.0), State(jobs=1)).state.clean_runs == {}
    assert decide(outcome(0.006), State(jobs=1, scale_factors={5: 0.5})).state.clean_runs == {}


def test_rule8_counts_a_clean_run_after_rule2_kept_the_scale():
    state = State(jobs=1, scale_factors={5: 0.5})
    d = decide(outcome(0.03, ours=0.001), state)  # all but 0.1% in host stalls
    assert d.state.clean_runs == {5: 1}


def test_decide_changes_nothing_it_is_given():
    state = State(jobs=3, load_limit=None, scale_factors={5: 0.5}, clean_runs={5: 2})
    before = copy.deepcopy(state)
    for o in (outcome(0.06), outcome(0.004), outcome(0.02, jobs_at_start=3)):
        decide(o, state)
    assert state == before


def test_calibration_goes_up_while_clean_and_down_while_late():
    from testbed.sweep.policy import MAX_SCALE_FACTOR, calibrated, calibration_next

    assert calibration_next([]) == 1.0
    up = [(1.0, 0.0)]
    assert calibration_next(up) > 1.0
    up += [(calibration_next(up), 0.02)]  # the second trial misses: stop, keep the first
    assert calibration_next(up) is None and calibrated(up) == 1.0
    assert calibration_next([(1.0, 0.008)]) is None  # within the limit: the file's scale
    assert calibrated([(1.0, 0.008)]) == 1.0
    down = [(1.0, 0.05)]
    assert calibration_next(down) == 0.85
    down += [(0.85, 0.002)]
    assert calibration_next(down) is None and calibrated(down) == 0.85
    top = [(MAX_SCALE_FACTOR, 0.0)]
    assert calibration_next([(1.0, 0.0), *top]) is None


def test_a_calibrated_ceiling_above_the_file_lets_a_slowed_team_climb_back_to_it():
    from testbed.sweep.policy import Outcome, State, decide

    s = State(jobs=1, scale_factors={3: 1.5}, ceilings={3: 2.0})
    for _ in range(3):
        s = decide(Outcome(robots=3, miss=0.0, miss_outside_stalls=0.0), s).state
    assert 1.5 < s.factor(3) <= 2.0


def test_rule7_an_unfaithful_run_alone_slows_its_team_size_and_is_redone_once():
    state = State(jobs=1)
    o = outcome(0.002, faithful=False, fidelity_reason="30% of plans late")
    d = decide(o, state)
    assert d.state.scale_factors == {5: SLOWDOWN} and d.redo
    assert d.backoffs == ({"deadline_miss_fraction": 0.002, "robots": 5,
                           "time_scale_factor": SLOWDOWN, "faithful": False},)  # fmt: skip
    assert d.words == (", not faithful (30% of plans late); time scales of teams of 5 down "
                       "to 85% of the file's, redoing it")  # fmt: skip
    # Redone once: the second attempt is kept whatever its verdict (and slows down again).
    again = decide(Outcome(5, 0.002, 0.002, faithful=False, attempts=2), d.state)
    assert not again.redo and again.state.factor(5) == pytest.approx(SLOWDOWN**2)


def test_rule7_an_unfaithful_shared_run_lowers_the_concurrency_or_the_load_limit():
    d = decide(outcome(0.0, faithful=False, shared=True, jobs_at_start=3), State(jobs=3))
    assert d.state.jobs == 2 and d.redo and d.state.scale_factors == {}
    d = decide(outcome(0.0, faithful=False, shared=True, load_seen=10.0),
               State(jobs=4, load_limit=20.0))  # fmt: skip
    assert d.state.load_limit == 8.0 and d.redo


def test_a_late_and_unfaithful_run_alone_is_redone_once_even_when_mildly_late():
    d = decide(outcome(0.02, faithful=False), State(jobs=1))
    assert d.redo and d.backoffs[0]["faithful"] is False
    assert not decide(outcome(0.02, faithful=True), State(jobs=1)).redo


def test_a_faithful_run_or_one_without_a_verdict_changes_nothing():
    for faithful in (True, None):
        d = decide(outcome(0.0, faithful=faithful), State(jobs=1))
        assert d == Decision(State(jobs=1))


def test_rule8_an_unfaithful_run_is_not_clean():
    state = State(jobs=1, scale_factors={5: 0.5})
    assert decide(outcome(0.0, faithful=True), state).state.clean_runs == {5: 1}
    assert decide(outcome(0.0, faithful=False), state).state.clean_runs == {5: 0}


def test_calibration_climbs_only_while_its_trials_stay_faithful():
    from testbed.sweep.policy import calibrated, calibration_next

    up = [(1.0, 0.0, True), (1.176, 0.0, True)]
    assert calibration_next(up) > 1.176
    up += [(calibration_next(up), 0.0, False)]  # in time, but its plans came late: stop
    assert calibration_next(up) is None and calibrated(up) == 1.176
    # Unfaithful at the file's scale: down until a trial is clean and faithful.
    down = [(1.0, 0.0, False)]
    assert calibration_next(down) == 0.85
    down += [(0.85, 0.0, False)]
    assert calibration_next(down) == pytest.approx(0.7225)
    down += [(0.7225, 0.001, True)]
    assert calibration_next(down) is None and calibrated(down) == 0.7225
    assert calibrated([(1.0, 0.0, False), (0.85, 0.0, False)]) == 0.85  # the lowest tried


def test_a_run_judged_not_faithful_is_redone_whatever_the_cause():
    """Its results changed with the dilation: whether its misses fell in host stalls, it ran
    shared or alone, or its team size is at its lowest scale, it is run again (once at
    least), never kept (the paper sweep kept n02-c15-l2-k3 at 25: its misses were in stalls)."""
    states = [
        State(jobs=1),
        State(jobs=2),
        State(jobs=1, load_limit=2.0, cpu_limit=1.5),
        State(jobs=1, scale_factors={2: MIN_SCALE_FACTOR}),
    ]
    seen = 0
    for state in states:
        for miss, outside in ((0.0, 0.0), (0.02, 0.0), (0.02, 0.005), (0.2, 0.1), (0.02, 0.02)):
            for shared in (False, True):
                o = outcome(miss, outside, faithful=False, robots=2, shared=shared,
                            jobs_at_start=2, load_seen=3.0, cpu_seen=1.8)  # fmt: skip
                d = decide(o, state)
                assert d.redo, (state, o, d)
                assert not decide(replace(o, attempts=3), state).redo
                seen += 1
    assert seen == 40
