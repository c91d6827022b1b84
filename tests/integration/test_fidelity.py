"""Time dilation against its ground truth (testbed.run.fidelity): a lone robot is
deterministic, so at two time scales where its verdict says faithful it must drive exactly
the same path; a run whose plans come late (the planner held back by a test hook) must be
judged unfaithful, and `testbed run` must say so in one line; and the network's timers are
recorded with the network's own verdict."""

import json
import os
import subprocess
import sys

import pytest

from aodv.statsfile import DaemonStats, run_stats_path

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
LONE = ["--robots", "1", "--comm-range", "20", "--laser-range", "2", "--seed", "1",
        "--routing", "aodv", "--quiet"]  # fmt: skip
STEPS = 300  # 15 plans: short, and long enough for a late plan to show in the path
HIGHER = (15, 10, 7.5)  # tried in turn until one is faithful (a loaded machine may need 7.5)
TRIES = 3  # runs at scale 5 until one is faithful


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
    """Under load a run may come out unfaithful (its verdict says so, and then its path
    differs: seen 3 times in 3 at scale 15 under a load average of 350, one or two of 15
    plans a step late); such a run proves nothing here, so a lower scale is tried."""
    verdicts = []
    slow = fast = None
    for k in range(TRIES):
        slow = lone_run(tmp_path / f"x5-{k}", tb_name, 5)
        verdicts.append((5, slow[1]["fidelity"].get("reason")))
        if slow[1]["fidelity"]["ok"]:
            break
    for scale in HIGHER:
        fast_out = tmp_path / f"x{scale}"
        fast = lone_run(fast_out, tb_name, scale)
        verdicts.append((scale, fast[1]["fidelity"].get("reason")))
        if fast[1]["fidelity"]["ok"]:
            break
    if not (slow[1]["fidelity"]["ok"] and fast[1]["fidelity"]["ok"]):
        pytest.fail(f"no faithful run at 5 and at a higher scale: {verdicts}")
    (_, low, low_path), (r, high, high_path) = slow, fast
    assert low["steps"] == high["steps"] == STEPS
    assert low_path == high_path  # every step's position, the same
    assert high["fidelity"]["measures"]["late_plans"] == 0
    assert high["fidelity"]["measures"]["plans"] >= 10
    assert "not faithful" not in r.stderr
    # The parts with deadlines ran at real-time priority wherever the world's clock did
    # (common.sched), and the daemons kept their most late timer firings with their times.
    with open(fast_out / "robots" / "r1.json") as fh:
        priority = json.load(fh)["priority"]
    assert set(priority) == {"motion", "planner", "timer"}
    if high["world_priority"].startswith("SCHED_RR"):
        assert set(priority.values()) == {"SCHED_RR 1"}
    lateness = DaemonStats.read(run_stats_path(fast_out, 1)).timer_lateness_ms
    assert lateness is not None
    hello = lateness["hello"]
    assert hello["n"] > 0 and 0 < len(hello["worst"]) <= hello["n"]
    assert all(fired >= due and ms >= 0 for due, fired, ms in hello["worst"])


def test_plans_that_come_late_make_a_run_unfaithful_and_testbed_run_says_so(tmp_path, tb_name):
    # 60 ms of wall time is 3 steps at time scale 5: every plan is applied two or three steps
    # late (the frame that comes as it is installed may have waited for it, node.robot).
    r, res, _ = lone_run(tmp_path / "late", tb_name, 5, NODE_PLAN_DELAY_MS="60")
    f = res["fidelity"]
    assert f["ok"] is False, f
    assert "plans applied a step or more late (100.0%, limit 1.0%)" in f["reason"]
    assert f["measures"]["late_plans"] == f["measures"]["plans"] > 0
    assert f["measures"]["plan_age_max_steps"] >= 2
    warnings = [line for line in r.stderr.splitlines() if "warning: not faithful" in line]
    assert len(warnings) == 1, r.stderr
    assert "at time scale 5:" in warnings[0] and f["reason"] in warnings[0]
    with open(tmp_path / "late" / "robots" / "r1.json") as fh:
        lateness = json.load(fh)["lateness"]
    assert lateness["plan_age_steps"]["hist"]["<=0"] == 0
    # The network's own verdict (fidelity.network): TCP's timers divided by 5 where the
    # kernel can, as the robot's namespace had them (result.json's network_timers).
    timers = res["network_timers"]
    assert timers["time_scale"] == 5
    rto = next(s for s in timers["settings"] if s["name"] == "tcp_rto_min")
    if os.path.exists("/proc/sys/net/ipv4/tcp_rto_min_us"):
        assert rto["status"] == "dilated" and rto["value"] < rto["default"]
        assert f["network"] == {"ok": True} and "note:" not in r.stderr
    else:
        assert rto["status"] == "missing" and f["network"]["ok"] is False
        assert "compare its PDF and delay only with runs at time scale 5" in r.stderr
