"""Sweeps on a real Slurm cluster (tests/slurm/cluster.py: one node, this machine).

The short sweep (testbed/experiments/short.toml) goes to Slurm with --slurm, its tasks run
`testbed run` on the node, and what lands in the sweep directory is what a local sweep of the
same file writes: the same runs, a report of the same structure. A task cancelled mid-run
is redone by --resume, and nothing else is."""

import json
import re
import subprocess
import sys
import time
import tomllib
from pathlib import Path

from testbed.files import slurmjobs

REPO = Path(__file__).resolve().parents[2]
SHORT = REPO / "testbed" / "experiments" / "short.toml"
SLOW = REPO / "tests" / "slurm" / "slow.toml"
FILE_SCALE = {
    int(n): float(v) for n, v in tomllib.loads(SHORT.read_text())["run"]["time_scale"].items()
}


def run_testbed(*args, timeout=1800):
    argv = [sys.executable, "-c", "import sys; from testbed.cli import main; sys.exit(main())"]
    return subprocess.run([*argv, *map(str, args)], cwd=REPO, capture_output=True, text=True,
                          timeout=timeout)  # fmt: skip


def status(out: Path) -> dict[str, str]:
    r = run_testbed("sweep", "--status", out)
    assert r.returncode == 0, r.stderr
    return dict(line.split("\t") for line in r.stdout.splitlines())


def wait_until(pred, timeout: float, what: str):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = pred()
        if value:
            return value
        time.sleep(1.0)
    raise AssertionError(f"timed out waiting for {what}")


def headings(report: Path) -> list[str]:
    """The report's section headings, less the first (it names the sweep directory) and less
    the verdicts some carry after a dash (two sweeps' runs differ by noise)."""
    lines = [line for line in report.read_text().splitlines() if line.startswith("#")][1:]
    return [line.split(" — ")[0] for line in lines]


def test_slurm_sweep_lands_like_a_local_one_and_reports(cluster, tmp_path):
    out = tmp_path / "slurm"
    r = run_testbed("sweep", SHORT, "--out", out, "--slurm", "--partition", "tb")
    assert r.returncode == 0, r.stderr
    jobs = slurmjobs.read(out).jobs
    assert [j.robots for j in jobs] == [1, 2, 3]  # one array per team size
    assert all(j.cpus >= 1 and j.minutes >= 1 for j in jobs)
    wait_until(lambda: set(status(out).values()) == {"done"}, 900, "every run done")
    assert run_testbed("report", out).returncode == 0

    local = tmp_path / "local"
    r = run_testbed("sweep", SHORT, "--out", local)
    assert r.returncode == 0, r.stderr
    assert run_testbed("report", local).returncode == 0
    runs = sorted(p.name for p in (out / "runs").iterdir())
    assert runs == sorted(p.name for p in (local / "runs").iterdir())
    for rid in runs:
        a = json.loads((out / "runs" / rid / "result.json").read_text())
        b = json.loads((local / "runs" / rid / "result.json").read_text())
        for doc in (a, b):
            doc["config"]["extra"].pop("name")  # the testbed's random name
        # A Slurm task runs at the file's time scale; a local sweep backs a team size off
        # below it when its runs miss deadlines on the shared cores (sweep.json "backoffs").
        file_scale = FILE_SCALE[a["config"]["robots"]]
        assert a["config"].pop("time_scale") == file_scale
        assert 0 < b["config"].pop("time_scale") <= file_scale
        assert a["config"] == b["config"] and set(a) == set(b)
    assert headings(out / "report.md") == headings(local / "report.md")
    figs = {p.name for p in (out / "figures").iterdir()}
    assert figs == {p.name for p in (local / "figures").iterdir()}


def test_a_cancelled_task_is_redone_by_resume_and_nothing_else(cluster, tmp_path):
    out = tmp_path / "cancel"
    r = run_testbed("sweep", SLOW, "--out", out, "--slurm")
    assert r.returncode == 0, r.stderr
    (job,) = slurmjobs.read(out).jobs
    victim, other = job.runs
    # Cancel the first task once its run is under way (its config.json is written).
    wait_until(lambda: (out / "runs" / victim / "config.json").exists(), 300, "run 1 to start")
    subprocess.run(["scancel", f"{job.job}_1"], check=True)
    wait_until(lambda: status(out).get(victim) == "failed", 120, "the cancelled task to end")
    assert not (out / "runs" / victim / "result.json").exists() or (
        json.loads((out / "runs" / victim / "result.json").read_text())["status"] == "interrupted"
    )
    # The report works while a task still runs, on what has finished (nothing, or one run).
    r = run_testbed("report", out)
    assert r.returncode == 0, r.stderr[-2000:]
    wait_until(lambda: status(out).get(other) == "done", 600, "the other run")
    done_at = (out / "runs" / other / "result.json").stat().st_mtime_ns

    r = run_testbed("sweep", SLOW, "--out", out, "--slurm", "--resume")
    assert r.returncode == 0, r.stderr
    assert re.search(r"1 submitted", r.stderr), r.stderr
    jobs = slurmjobs.read(out).jobs
    assert jobs[-1].runs == (victim,)  # exactly the cancelled run
    wait_until(lambda: set(status(out).values()) == {"done"}, 600, "the redone run")
    assert (out / "runs" / other / "result.json").stat().st_mtime_ns == done_at
    assert json.loads((out / "runs" / victim / "result.json").read_text())["status"] in (
        "complete", "step_cap",
    )  # fmt: skip
