"""Time dilation against its ground truth (testbed.fidelity): a lone robot is
deterministic, so at two time scales where its verdict says faithful it must drive exactly
the same path; a run whose plans come late (the planner held back by a test hook) must be
judged unfaithful, and `testbed run` must say so in one line."""

import json
import os
import subprocess
import sys

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
LONE = ["--robots", "1", "--comm-range", "20", "--laser-range", "2", "--seed", "1",
        "--routing", "aodv", "--quiet"]  # fmt: skip
STEPS = 300  # 15 plans: short, and long enough for a late plan to show in the path
TRIES = 3  # a loaded machine may make either run of a pair unfaithful: such a pair is redone


def lone_run(out, name, scale, **env):
    r = subprocess.run(
        [sys.executable, "-m", "testbed.cli", "run", *LONE, "--time-scale", str(scale),
         "--max-steps", str(STEPS), "--out", str(out), "--name", name],
        capture_output=True, text=True, cwd=REPO, timeout=600, env={**os.environ, **env},
    )  # fmt: skip
    assert r.returncode in (0, 1), r.stderr  # 1: the step cap (the robot was not done)
    with open(out / "result.json") as f:
        result = json.load(f)
    return r, result, (out / "positions.csv").read_text()


def test_a_lone_robot_drives_the_same_path_at_a_low_and_a_higher_faithful_scale(tmp_path, tb_name):
    verdicts = []
    for k in range(TRIES):
        runs = [lone_run(tmp_path / f"x{scale}-{k}", tb_name, scale) for scale in (5, 15)]
        verdicts.append([res["fidelity"] for _, res, _ in runs])
        if all(res["fidelity"]["ok"] for _, res, _ in runs):
            break
    else:
        pytest.fail(f"no pair of faithful runs at 5 and 15 in {TRIES} tries: {verdicts}")
    (_, slow, slow_path), (r, fast, fast_path) = runs
    assert slow["steps"] == fast["steps"] == STEPS
    assert slow_path == fast_path  # every step's position, the same
    assert fast["fidelity"]["measures"]["late_plans"] == 0
    assert fast["fidelity"]["measures"]["plans"] >= 10
    assert "not faithful" not in r.stderr


def test_plans_that_come_late_make_a_run_unfaithful_and_testbed_run_says_so(tmp_path, tb_name):
    # 60 ms of wall time is 3 steps at time scale 5: every plan is applied 3 steps late.
    r, res, _ = lone_run(tmp_path / "late", tb_name, 5, NODE_PLAN_DELAY_MS="60")
    f = res["fidelity"]
    assert f["ok"] is False, f
    assert "of plans applied a step or more late" in f["reason"]
    assert f["measures"]["late_plans"] == f["measures"]["plans"] > 0
    assert f["measures"]["plan_age_max_steps"] >= 3
    warnings = [line for line in r.stderr.splitlines() if "warning: not faithful" in line]
    assert len(warnings) == 1, r.stderr
    assert "at time scale 5:" in warnings[0] and f["reason"] in warnings[0]
    with open(tmp_path / "late" / "robots" / "r1.json") as fh:
        lateness = json.load(fh)["lateness"]
    assert lateness["plan_age_steps"]["hist"]["<=0"] == 0
