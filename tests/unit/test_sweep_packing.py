"""Packing runs by their estimated cores (a sweep file's cpu_limit): which waiting run the
sweep admits beside the runs in flight, the job cap, and what a resumed sweep learns from the
runs already done. The runs themselves, with a stand-in for `testbed run`, are in
test_sweep_runner.py."""

import io
import json
from collections import deque

import pytest

from testbed.sweep import plan as sweepplan
from testbed.sweep.cores import PRIOR_CORES_PER_LOAD, Measured
from testbed.sweep.file import SweepSpec, expand
from testbed.sweep.plan import run_load
from testbed.sweep.runner import Sweep, _Child
from tests.unit.test_sweep_synthetic import write_run

C = 0.04  # cores per unit of load the sweeps below have measured: a lone robot at 5 is 0.4


def make_sweep(tmp_path, robots=(1, 2, 4), **limits) -> Sweep:
    spec = SweepSpec.of(robots=robots, comm_range=(5.0, 20.0), laser_range=(2.0,),
                        time_scale=5.0, **limits)  # fmt: skip
    sweep = Sweep(spec, expand(spec), tmp_path, 4, False, command=["true"],
                  progress_stream=io.StringIO())  # fmt: skip
    sweep.measured = [Measured(n, C) for n in robots]
    return sweep


def run_of(sweep: Sweep, robots: int, comm: float = 5.0):
    return next(r for r in sweep.runs if (r.config.robots, r.config.comm_range) == (robots, comm))


def in_flight(sweep: Sweep, *runs) -> dict:
    """Children for `runs`, as the sweep would hold them (no process behind them)."""
    return {
        r.run_id: _Child(
            r, None, 0.0, sweep.jobs, None, load=run_load(r), cores=sweep._estimate(r)
        )  # fmt: skip
        for r in runs
    }


def test_two_light_runs_share_the_machine_under_the_cpu_limit(tmp_path):
    s = make_sweep(tmp_path, cpu_limit=1.0)
    one, other = run_of(s, 1, 5.0), run_of(s, 1, 20.0)
    assert s._estimate(one) == pytest.approx(0.4)
    queue = deque([other])
    assert s._next_fitting(queue, in_flight(s, one)) == other and not queue


def test_a_pair_over_the_cpu_limit_is_refused(tmp_path):
    s = make_sweep(tmp_path, cpu_limit=1.0)
    two, other_two = run_of(s, 2, 5.0), run_of(s, 2, 20.0)  # 0.6 cores each
    queue = deque([other_two])
    assert s._next_fitting(queue, in_flight(s, two)) is None
    assert list(queue) == [other_two]


def test_the_first_waiting_run_that_fits_starts(tmp_path):
    s = make_sweep(tmp_path, cpu_limit=1.0)
    big, small = run_of(s, 4), run_of(s, 1, 20.0)  # 1.0 and 0.4 cores
    queue = deque([big, small])
    assert s._next_fitting(queue, in_flight(s, run_of(s, 1, 5.0))) == small
    assert list(queue) == [big]


def test_a_run_over_the_limit_starts_when_nothing_is_in_flight(tmp_path):
    s = make_sweep(tmp_path, cpu_limit=0.5)
    big = run_of(s, 4)
    assert s._estimate(big) > 0.5
    assert s._next_fitting(deque([big]), {}) == big


@pytest.mark.parametrize(
    "limits",
    [
        {"cpu_limit": 1.0, "load_limit": 15.0},  # the cores fit (0.8), the loads not (20)
        {"cpu_limit": 0.7, "load_limit": 25.0},  # the loads fit, the cores not
    ],
)
def test_a_run_must_fit_both_limits(tmp_path, limits):
    s = make_sweep(tmp_path, **limits)
    one, other = run_of(s, 1, 5.0), run_of(s, 1, 20.0)
    assert s._next_fitting(deque([other]), in_flight(s, one)) is None
    roomier = make_sweep(tmp_path, cpu_limit=1.0, load_limit=25.0)
    assert roomier._next_fitting(deque([other]), in_flight(roomier, one)) == other


def test_the_estimate_is_at_the_time_scale_the_run_will_get(tmp_path):
    s = make_sweep(tmp_path, cpu_limit=1.0)
    one = run_of(s, 1)
    s.scale_factors = {1: 0.5}  # the policy slowed lone robots down to half the file's scale
    assert s._estimate(one) == pytest.approx(C * 2 * 2.5)
    assert s._estimate(run_of(s, 2)) == pytest.approx(C * 3 * 5.0)


def test_the_prior_until_a_run_has_measured(tmp_path):
    s = make_sweep(tmp_path, cpu_limit=1.0)
    s.measured = []
    assert s._estimate(run_of(s, 2)) == pytest.approx(PRIOR_CORES_PER_LOAD * 3 * 5.0)


def done_doc(run, cores: float, wall: float = 50.0, cpu: bool = True) -> dict:
    """result.json of a finished run that kept `cores` cores busy while stepping."""
    c = run.config
    doc = {
        "format": 1, "status": "complete", "steps": 500,
        "config": {"robots": c.robots, "comm_range": c.comm_range,
                   "laser_range": c.laser_range, "time_scale": c.time_scale},
        "time_scale_requested": c.time_scale, "time_scale_achieved": c.time_scale,
        "wall_parts_s": {"steps": wall},
    }  # fmt: skip
    if cpu:
        doc["cpu_s"] = {"robots": cores * wall * 0.75, "display": cores * wall * 0.25}
    return doc


def test_a_resumed_sweep_learns_from_the_runs_already_done(tmp_path):
    s = make_sweep(tmp_path, robots=(1, 2), cpu_limit=1.5)
    s.measured = []
    one, two, older = run_of(s, 1, 5.0), run_of(s, 2, 5.0), run_of(s, 1, 20.0)
    write_run(tmp_path, one, done_doc(one, cores=0.5))
    write_run(tmp_path, two, done_doc(two, cores=0.9))
    write_run(tmp_path, older, done_doc(older, cores=0.0, cpu=False))  # made before cpu_s
    assert s.run([], [one, two, older], {}) == 0
    assert s.measured == [Measured(1, pytest.approx(0.5 / 10)), Measured(2, pytest.approx(0.06))]
    assert s._estimate(run_of(s, 2, 20.0)) == pytest.approx(0.9)
    state = json.loads((tmp_path / "sweep.json").read_text())
    runs = {r["id"]: r for r in state["runs"]}
    assert runs[one.run_id]["cores_measured"] == 0.5
    assert runs[two.run_id]["cores_measured"] == 0.9
    assert "cores_measured" not in runs[older.run_id]
    assert state["cpu_limit_requested"] == state["cpu_limit"] == 1.5


@pytest.mark.parametrize(
    "requested, cpu_limit, cores, jobs",
    [
        (None, 1.8, 2, 2),  # packing by cores: the core count caps, the limit decides
        (None, 1.8, 8, 8),
        (None, None, 2, 1),  # else half the cores, as before
        (None, None, 8, 4),
        (3, 1.8, 2, 3),  # an explicit --jobs still caps
        (1, 1.8, 8, 1),
    ],
)
def test_the_job_cap(requested, cpu_limit, cores, jobs):
    assert sweepplan.jobs_cap(requested, [], cpu_limit, cores=cores) == jobs


def test_the_job_cap_of_jobs_auto_is_auto_jobs_with_a_cpu_limit_too():
    spec = SweepSpec.of(robots=(1, 10), comm_range=(5.0,), laser_range=(2.0,), time_scale=20.0)
    runs = expand(spec)
    for cores in (2, 64):
        assert sweepplan.jobs_cap("auto", runs, 1.8, cores) == sweepplan.auto_jobs(runs, cores)


def test_tails_do_not_count_in_flight_but_cannot_pile_up(tmp_path):
    """A run in its tail leaves room for the next one under --jobs 1 and the cpu limit; more
    tails than --jobs count again (a hung teardown), as do all tails for a team size that
    waits for them and under --view."""
    s = make_sweep(tmp_path, cpu_limit=0.5)
    s.schedule.jobs = 1
    one, other, two = run_of(s, 1, 5.0), run_of(s, 1, 20.0), run_of(s, 2, 5.0)
    flying = in_flight(s, one)
    assert s._next_fitting(deque([other]), flying) is None  # 0.8 cores > 0.5, and jobs
    flying[one.run_id].tail = True
    assert s._next_fitting(deque([other]), flying) == other
    both = in_flight(s, one, two)
    for c in both.values():
        c.tail = True
    assert s._next_fitting(deque([other]), both) is None  # two tails, one job
    s.schedule.no_overlap = frozenset({1})
    assert s._next_fitting(deque([other]), flying) is None
    s.schedule.no_overlap = frozenset()
    s.schedule.tails_wait = True
    assert s._next_fitting(deque([other]), flying) is None
