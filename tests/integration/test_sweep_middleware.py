"""The middleware sweep in small (middleware-short.toml: 2 robots, each middleware without a
failure and with r2 killed at mid-run), swept in real namespaces and reported: the failure
goes through the run's kill list at the step fixed before the run, and the report's
middlewares section has a row per failure and middleware and decides nothing on one run."""

import json
import os
from pathlib import Path

import pytest

from testbed.files import failures
from testbed.sweep import file as sweepfile
from tests.integration.test_sweep_short import results, run_testbed

REPO = Path(__file__).resolve().parents[2]
SHORT = REPO / "testbed" / "experiments" / "middleware-short.toml"

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(os.geteuid() != 0, reason="needs root (network namespaces)"),
]


def test_middleware_short_sweep_and_report(tmp_path):
    from node.messaging import MIDDLEWARES, unavailable

    missing = [m for m in MIDDLEWARES if unavailable(m)]
    if missing:
        pytest.skip(f"middleware packages missing: {missing} (make setup installs them)")
    out = tmp_path / "mw"
    r = run_testbed("sweep", SHORT, "--out", out, timeout=900)
    assert r.returncode == 0, r.stderr[-2000:]
    res = results(out)
    planned = {p.run_id: p for p in sweepfile.expand(sweepfile.load(SHORT))}
    assert set(res) == set(planned)
    step = failures.midrun_step(2, 2.0)
    for rid, doc in res.items():
        c = planned[rid].config
        assert doc["messaging"]["middleware"] == c.middleware
        stopped = {k: v["stopped_step"] for k, v in doc["robots"].items()}
        if c.battery_failure == "midrun":
            assert rid.endswith("-midrun-k1") and stopped == {"r1": None, "r2": step}
            assert doc["config"]["extra"]["battery_kill"] == f"r2:{step}"
            assert doc["mean_finish_step_robots"] == 1
            assert doc["messaging"]["robots"]["r2"] is None  # killed: no counters
        else:
            assert "midrun" not in rid and stopped == {"r1": None, "r2": None}
        assert doc["status"] in ("complete", "step_cap"), (rid, doc["status_detail"])
    # The failure variants share the point's seed.
    seeds = {(p.config.middleware, p.config.battery_failure): p.config.seed
             for p in planned.values()}  # fmt: skip
    assert len(set(seeds.values())) == 1

    r = run_testbed("report", out, "--include-unfaithful", timeout=900)
    assert r.returncode == 0, r.stderr[-2000:]
    text = (out / "report.md").read_text()
    assert "## Which middleware a team can rely on (the paper's Section 3)" in text
    for mw in MIDDLEWARES:
        for failure in ("none", "midrun"):
            assert f"| 2 | 20 | {failure} | {mw} | 1 | 0 | " in text, (mw, failure)
    assert "**Does the paper's claim hold?** too few runs to decide" in text
    rows = json.loads((out / "figures" / "middlewares.json").read_text())
    nanomsg = next(
        r for r in rows if (r["middleware"], r["battery_failure"]) == ("nanomsg", "none")
    )
    assert nanomsg["air_bytes_per_robot_s"] > 0 and 0 < nanomsg["air_own_share"] < 1
    assert 0 < nanomsg["delivery"] <= 1
