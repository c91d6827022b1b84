"""Estimated cores of a planned run (testbed.sweep.cores) and the measurement it learns from
(RunResult.cores_while_stepping), pure."""

import math

import pytest

from testbed.files.resultfile import RunResult
from testbed.sweep import cores
from testbed.sweep.cores import PRIOR_CORES_PER_LOAD, Measured, estimate, measure
from testbed.sweep.file import SweepSpec, expand
from testbed.sweep.slurm import resources


def result(robots=2, scale=10.0, achieved=None, cpu=None, wall=None) -> RunResult:
    doc = {
        "status": "complete",
        "config": {"robots": robots, "comm_range": 5.0, "laser_range": 2.0,
                   "time_scale": scale},
        "time_scale_requested": scale,
        "time_scale_achieved": achieved if achieved is not None else scale,
    }  # fmt: skip
    if cpu is not None:
        doc["cpu_s"] = cpu
    if wall is not None:
        doc["wall_parts_s"] = {"network_up": 3.0, "steps": wall, "teardown": 2.0}
    return RunResult.from_json(doc)


CPU = {"robots": 30.0, "display": 4.0, "world": 5.0, "routing": 1.0, "per_robot_step_ms": 7.5}


def test_cores_while_stepping_is_the_cpu_of_the_parts_over_the_stepping_wall_time():
    assert result(cpu=CPU, wall=80.0).cores_while_stepping == pytest.approx(40.0 / 80.0)
    # a part the file lacks counts nothing; per_robot_step_ms is not a part
    assert result(cpu={"robots": 12.0}, wall=10.0).cores_while_stepping == pytest.approx(1.2)


@pytest.mark.parametrize(
    "cpu, wall",
    [(None, 80.0), (CPU, None), (CPU, 0.0), ({"per_robot_step_ms": 2.0}, 80.0), ({}, 80.0)],
)
def test_cores_while_stepping_is_none_without_cpu_or_stepping_time(cpu, wall):
    assert result(cpu=cpu, wall=wall).cores_while_stepping is None


def test_the_prior_is_slurms_cpu_per_robot_step_with_its_margin_without_the_reserved_core():
    """Before any run has finished: what testbed.sweep.slurm.resources sizes a cluster task
    by, less the whole core it reserves for the world (a run does not keep it busy)."""
    spec = SweepSpec.of(robots=(9,), comm_range=(5.0,), laser_range=(2.0,), time_scale=20.0)
    run = expand(spec)[0]
    cpus, _ = resources(run.config)
    assert estimate(9, 20.0, []) == pytest.approx(PRIOR_CORES_PER_LOAD * 10 * 20.0)
    assert cpus == math.ceil(estimate(9, 20.0, []) + 1)  # + the world's core, rounded up
    assert estimate(1, 5.0, []) == pytest.approx(PRIOR_CORES_PER_LOAD * 2 * 5.0)


def test_measure_divides_the_cores_by_the_load_at_the_achieved_time_scale():
    m = measure(result(robots=3, scale=10.0, cpu={"robots": 16.0}, wall=10.0))
    assert m == Measured(3, pytest.approx(1.6 / (4 * 10.0)))
    # it fell behind: 8 steps a second, not 10: its CPU is that of the smaller load
    slow = measure(result(robots=3, scale=10.0, achieved=8.0, cpu={"robots": 16.0}, wall=10.0))
    assert slow.cores_per_load == pytest.approx(1.6 / (4 * 8.0))


def test_measure_ignores_a_run_without_cpu_data():
    assert measure(result(cpu=None, wall=10.0)) is None
    assert measure(result(cpu=CPU, wall=None)) is None


def test_learnt_from_runs_of_the_same_team_size_by_their_median():
    seen = [Measured(2, 0.01), Measured(2, 0.05), Measured(2, 0.02), Measured(8, 0.5)]
    assert cores.cores_per_load(2, seen) == pytest.approx(0.02)
    assert estimate(2, 10.0, seen) == pytest.approx(0.02 * 3 * 10.0)


def test_learnt_from_other_team_sizes_when_none_of_its_own_has_finished():
    seen = [Measured(2, 0.01), Measured(2, 0.03), Measured(8, 0.02), Measured(8, 0.5)]
    assert cores.cores_per_load(5, seen) == pytest.approx(0.025)
    assert estimate(5, 4.0, seen) == pytest.approx(0.025 * 6 * 4.0)


def test_the_estimate_grows_with_team_size_and_time_scale():
    seen = [Measured(4, 0.03)]
    assert estimate(4, 10.0, seen) == pytest.approx(2 * estimate(4, 5.0, seen))
    assert estimate(4, 10.0, seen) < estimate(9, 10.0, seen)
