"""Synthetic sweep directories that follow docs/run-results.md exactly, for the figure, report
and sweep tests; and tests that what they write is what the contract says."""

import json
import os
from pathlib import Path

from testbed.sweep import file as sweepfile
from testbed.sweep.rundir import plan_dict


def paper_like_steps(robots: int, comm: float, laser: float, index: int) -> float:
    """A known shape: fall then rise with team size (minimum at 5), more steps for a smaller
    range and a shorter laser (x 2/laser, the same ratio at every team size)."""
    base = 1200.0 / robots + 40.0 * robots
    return base * (1 + 4.0 / comm) * (2.0 / laser) + 3.0 * (index - 2)


def result_doc(config: dict, finish: list[int | None], steps: int, plans=None, status="complete",
               miss=0.0) -> dict:  # fmt: skip
    if not isinstance(config, dict):
        config = plan_dict(config)  # a PlannedRun's RunConfig, as sweep.json records it
    robots = {}
    for k, fs in enumerate(finish, start=1):
        robots[f"r{k}"] = {
            "finish_step": fs,
            "crashed": False,
            "exit_status": 0,
            "plans": (plans or {}).get(k, [{"step": 0, "cause": "start"}]),
            "messages": {"sent": {"goal": 1, "map": 2}, "received": {"goal": 1, "map": 2}},
            "path_length_m": 10.0,
        }
    return {
        "format": 1,
        "config": config,
        "status": status,
        "status_detail": "",
        "steps": steps,
        "coverage_final": 0.99,
        "time_scale_requested": config["time_scale"],
        "time_scale_achieved": config["time_scale"],
        "deadlines_missed": 0,
        "deadline_miss_fraction": miss,
        "wall_time_s": 1.0,
        "robots": robots,
    }


def timer_plans(final: int, requests: int = 0, period: int = 20) -> list[dict]:
    plans = [{"step": 0, "cause": "start"}]
    plans += [{"step": s, "cause": "timer"} for s in range(period, final, period)]
    plans += [{"step": 7 + 20 * i, "cause": "request"} for i in range(requests)]
    return sorted(plans, key=lambda p: p["step"])


def write_run(out: Path, run: sweepfile.PlannedRun, doc: dict | None = None) -> Path:
    """Write a finished run as `testbed run` would: config.json first, result.json last via
    an atomic rename."""
    d = out / "runs" / run.run_id
    d.mkdir(parents=True)
    (d / "config.json").write_text(json.dumps(plan_dict(run.config)))
    if doc is None:
        c = run.config
        total = paper_like_steps(c.robots, c.comm_range, c.laser_range, run.index)
        # finish steps whose mean is exactly `total`: spread symmetrically around it
        n = c.robots
        offsets = [(k - (n - 1) / 2) * 2 for k in range(n)]
        finish = [total + o for o in offsets]
        final = int(max(finish)) + 1
        plans = {k: timer_plans(final, requests=(n - 1) * 2) for k in range(1, n + 1)}
        doc = result_doc(c, finish, final, plans)
    tmp = d / "result.json.tmp"
    tmp.write_text(json.dumps(doc))
    os.replace(tmp, d / "result.json")
    return d


def make_sweep(out: Path, spec: sweepfile.SweepSpec) -> list[sweepfile.PlannedRun]:
    runs = sweepfile.expand(spec)
    for run in runs:
        write_run(out, run)
    return runs


def test_synthetic_runs_follow_the_contract(tmp_path):
    spec = sweepfile.SweepSpec.of(robots=(1, 3), comm_range=(5.0,), laser_range=(2.0,), runs=2)
    runs = make_sweep(tmp_path, spec)
    for run in runs:
        d = tmp_path / "runs" / run.run_id
        doc = json.loads((d / "result.json").read_text())
        assert doc["config"] == json.loads((d / "config.json").read_text()) == plan_dict(run.config)
        assert set(doc["robots"]) == {f"r{k}" for k in range(1, run.config.robots + 1)}
        assert not (d / "result.json.tmp").exists()
        steps = [r["finish_step"] for r in doc["robots"].values()]
        c = run.config
        expected = paper_like_steps(c.robots, c.comm_range, c.laser_range, run.index)
        assert abs(sum(steps) / len(steps) - expected) < 1e-9
