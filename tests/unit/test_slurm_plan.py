"""What a --slurm sweep asks of the cluster per run, and the batch script it submits."""

import json
from pathlib import Path

from testbed.files import slurmjobs
from testbed.files.runconfig import RunConfig
from testbed.sweep import slurm


def test_resources_grow_with_team_and_time_scale_and_fit_a_node():
    small = slurm.resources(RunConfig(robots=1, comm_range=5.0, time_scale=15, max_steps=6000))
    big = slurm.resources(RunConfig(robots=10, comm_range=5.0, time_scale=3.75, max_steps=6000))
    fast_big = slurm.resources(RunConfig(robots=10, comm_range=5.0, time_scale=15, max_steps=6000))
    assert small[0] >= 1 and big[0] >= 2 and fast_big[0] > big[0]
    # The time limit covers the step cap at the run's pace, with margin and start-up.
    assert big[1] >= 6000 * 0.1 / 3.75 * 3 / 60
    assert small[1] < big[1]
    crowd = RunConfig(robots=50, comm_range=5.0, time_scale=15, max_steps=10)
    assert slurm.resources(crowd, 8)[0] == 8


def test_batch_script_runs_one_task_of_the_list_with_this_python(tmp_path):
    text = slurm.batch_script(tmp_path / "out dir", tmp_path / "tasks-1.txt")
    assert text.startswith("#!/bin/sh\n")
    assert "-m testbed.sweep.slurm task" in text and '"$SLURM_ARRAY_TASK_ID"' in text
    assert "'" + str(tmp_path / "out dir") + "'" in text  # quoted: paths may hold spaces
    checkout = Path(__file__).resolve().parents[2]  # the tasks start in the checkout
    assert f"cd {checkout} ||" in text
    assert "exec sudo -n " in slurm.batch_script(tmp_path, tmp_path / "t.txt", sudo=True)


def test_a_task_index_outside_its_list_is_refused(tmp_path):
    tasks = tmp_path / "tasks.txt"
    tasks.write_text("n01-c5-l2-k1\n")
    assert slurm.task_main(tmp_path, tasks, 2) == 2
    assert slurm.task_main(tmp_path, tasks, 1) == 2  # no sweep.json: not planned


def test_a_cancelled_run_is_recorded_as_interrupted_whatever_it_ended_with(tmp_path):
    import json

    config = {"robots": 2, "comm_range": 5.0, "laser_range": 2.0}
    (tmp_path / "result.json").write_text(
        json.dumps({"status": "error", "status_detail": "the fork server died", "config": config})
    )
    slurm._mark_interrupted(tmp_path)
    doc = json.loads((tmp_path / "result.json").read_text())
    assert doc["status"] == "interrupted" and "SIGTERM" in doc["status_detail"]
    assert "the fork server died" in doc["status_detail"]


def test_submit_makes_one_array_per_team_size_from_the_planned_configs(tmp_path, monkeypatch):
    """Stand-ins for sinfo and sbatch on PATH (real programs, recording their arguments)."""
    import os

    from testbed.sweep import file as sweepfile

    bindir = tmp_path / "bin"
    bindir.mkdir()
    (bindir / "sinfo").write_text("#!/bin/sh\necho 64\n")
    (bindir / "sbatch").write_text(
        f'#!/bin/sh\necho "$@" >> {tmp_path}/sbatch.log\nwc -l < {tmp_path}/sbatch.log\n'
    )
    for tool in ("sinfo", "sbatch"):
        (bindir / tool).chmod(0o755)
    monkeypatch.setenv("PATH", f"{bindir}:{os.environ['PATH']}")
    scales = ((1, 15.0), (4, 9.0))
    spec = sweepfile.SweepSpec.of(robots=(1, 4), comm_range=(5.0, 10.0), laser_range=(2.0,),
                               time_scale_by_robots=scales, max_steps=6000)  # fmt: skip
    runs = sweepfile.expand(spec)
    out = tmp_path / "out"
    jobs = slurm.submit(out, runs, partition="p1")
    assert [(j.job, j.robots) for j in jobs] == [(1, 1), (2, 4)]
    lines = (tmp_path / "sbatch.log").read_text().splitlines()
    for job, line in zip(jobs, lines, strict=True):
        team = [r for r in runs if r.config.robots == job.robots]
        assert job.runs == tuple(r.run_id for r in team)
        cpus, minutes = slurm.resources(team[0].config, 64)
        assert f"--array=1-{len(team)}" in line and f"--cpus-per-task={cpus}" in line
        assert f"--time={minutes}" in line and "--partition=p1" in line
    assert slurmjobs.read(out).jobs == jobs


def test_sizing_uses_the_cpu_per_robot_step_the_sweeps_runs_measured(tmp_path):
    assert slurm.measured_cpu_per_robot_step(tmp_path) is None
    for name, ms in (("a", 1.2), ("b", 3.0), ("c", None)):
        d = tmp_path / "runs" / name
        d.mkdir(parents=True)
        cpu = {} if ms is None else {"per_robot_step_ms": ms}
        config = {"robots": 2, "comm_range": 5.0, "laser_range": 2.0}
        (d / "result.json").write_text(
            json.dumps({"status": "complete", "config": config, "cpu_s": cpu})
        )
    assert slurm.measured_cpu_per_robot_step(tmp_path) == 0.003
    config = RunConfig(robots=10, comm_range=5.0, time_scale=15, max_steps=6000)
    assert slurm.resources(config, cpu_per_robot_step=0.003)[0] > slurm.resources(config)[0]
    # The default is what was measured here: 10 robots at 15 need 5 cores, not 11.
    assert slurm.resources(config)[0] == 5
