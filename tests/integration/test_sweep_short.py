"""Sweeps of real runs (`testbed run` in namespaces): the short profile end to end, and a
sweep interrupted by SIGINT or SIGKILL and resumed.

Both are slow (minutes). The interrupted sweep is checked against its plan, which is exactly
what an uninterrupted sweep of the same file produces (tests/unit/test_sweep_runner.py checks
that equivalence against an actual uninterrupted sweep, with a stand-in for `testbed run`).
"""

import json
import os
import shutil
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path

import pytest

from testbed.sweep import file as sweepfile
from testbed.sweep.rundir import plan_dict

REPO = Path(__file__).resolve().parents[2]
SHORT = REPO / "testbed" / "experiments" / "short.toml"

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(os.geteuid() != 0, reason="needs root (network namespaces)"),
]


def run_testbed(*args, timeout=3600, **kw):
    argv = [sys.executable, "-c", "import sys; from testbed.cli import main; sys.exit(main())"]
    return subprocess.run(
        [*argv, *map(str, args)], cwd=REPO, capture_output=True, text=True, timeout=timeout, **kw
    )


def results(out: Path) -> dict:
    return {p.parent.name: json.loads(p.read_text()) for p in out.glob("runs/*/result.json")}


def report_all(out: Path):
    """The report with every run counted: these tests check that each figure and section is
    made from every run's files. Whether a run kept faithful to its time scale depends on
    the machine's load (tests/integration/test_fidelity.py tests the verdict); here every
    run carries one, and the report names the unfaithful ones, however many."""
    r = run_testbed("report", out, "--include-unfaithful", timeout=900)
    assert r.returncode == 0, r.stderr[-2000:]
    res = results(out)
    assert all(isinstance(d["fidelity"]["ok"], bool) for d in res.values())
    unfaithful = [rid for rid, d in res.items() if not d["fidelity"]["ok"]]
    text = (out / "report.md").read_text()
    assert (f"Not faithful to their time scale: {len(unfaithful)} run(s)" in text) == bool(
        unfaithful
    )
    return r


def test_short_profile_end_to_end(tmp_path):
    out = tmp_path / "short"
    r = run_testbed("sweep", SHORT, "--out", out)
    assert r.returncode == 0, r.stderr[-2000:]
    report_all(out)
    figs = out / "figures"
    for name in ("fig2a", "fig4", "routing"):
        assert (figs / f"{name}.png").is_file() and (figs / f"{name}.pdf").is_file()
    assert (out / "report.md").is_file()
    assert len(list((figs / "paths").glob("*.png"))) == 6

    # The numbers behind Fig. 2 against the runs' own result.json.
    res = results(out)
    assert len(res) == 6
    for row in json.loads((figs / "fig2.json").read_text()):
        per_run = []
        for rid in row["runs"]:
            doc = res[rid]
            fs = [
                r["finish_step"] if r["finish_step"] is not None else doc["steps"]
                for r in doc["robots"].values()
            ]
            per_run.append(statistics.fmean(fs))
            c = doc["config"]
            assert (c["robots"], c["comm_range"], c["laser_range"]) == (
                row["robots"],
                row["comm_range"],
                row["laser_range"],
            )
        assert row["mean"] == pytest.approx(statistics.fmean(per_run))

    # Routing metrics exist for every run, and agree with the daemons' own counters.
    routing = json.loads((figs / "routing_runs.json").read_text())
    assert len(routing) == 6
    for row in routing:
        assert 0 <= row["overhead_packets"] < 1
        if row["robots"] > 1:  # a lone robot has nobody to route to: no AODV traffic at all
            assert row["control_tx_packets"] > 0 and row["pdf"] > 0
        if row["daemon_relative_difference"] is not None:
            assert row["daemon_relative_difference"] <= 0.01, row


INTERRUPT_SWEEP = """
[grid]
robots = [1, 2]
comm_range = [5, 20]
laser_range = [2.0]
runs = 1

[run]
time_scale = 5
routing = "babel"
max_steps = 150
capture = false
"""


def namespaces() -> set[str]:
    out = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True).stdout
    return {line.split()[0] for line in out.splitlines() if line.strip()}


def processes_mentioning(text: str) -> list[int]:
    pids = []
    for p in Path("/proc").iterdir():
        if not p.name.isdigit() or int(p.name) == os.getpid():
            continue
        try:
            if text.encode() in (p / "cmdline").read_bytes():
                pids.append(int(p.name))
        except OSError:
            continue
    return pids


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGKILL], ids=["SIGINT", "SIGKILL"])
def test_interrupted_sweep_resumes_to_the_same_results(tmp_path, sig):
    f = tmp_path / "s.toml"
    f.write_text(INTERRUPT_SWEEP)
    plan = {r.run_id: plan_dict(r.config) for r in sweepfile.expand(sweepfile.load(f))}
    out = tmp_path / "out"
    argv = [sys.executable, "-c", "import sys; from testbed.cli import main; sys.exit(main())"]
    p = subprocess.Popen(
        [*argv, "sweep", str(f), "--out", str(out), "--jobs", "1"],
        cwd=REPO,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        # interrupt while the second run is in flight
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline:
            in_flight = [d for d in out.glob("runs/*") if not (d / "result.json").exists()]
            if results(out) and in_flight and (in_flight[0] / "config.json").exists():
                break
            time.sleep(0.2)
        else:
            pytest.fail("the sweep never got to its second run")
        victim = in_flight[0]
        name = json.loads((victim / "config.json").read_text())["name"]
        time.sleep(1.0)
        p.send_signal(sig)
        p.wait(timeout=120)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    # Finished before the stop (the run cut short records "interrupted" and is redone).
    done_before = {
        k: (out / "runs" / k / "result.json").stat().st_mtime_ns
        for k, doc in results(out).items()
        if doc["status"] != "interrupted"
    }
    assert 1 <= len(done_before) < len(plan)
    # The interrupted run cleaned up after itself: no namespace, no process left.
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and (
        any(ns.startswith(f"tb-{name}-") for ns in namespaces())
        or processes_mentioning(str(victim))
    ):
        time.sleep(0.5)
    assert not any(ns.startswith(f"tb-{name}-") for ns in namespaces())
    assert not processes_mentioning(str(victim))

    r = run_testbed("sweep", f, "--out", out, "--resume", "--jobs", "1")
    assert r.returncode == 0, r.stderr[-2000:]
    final = results(out)
    assert set(final) == set(plan)
    # Every run is a finished one: the run interrupted mid-way was redone, not kept.
    assert all(doc["status"] in ("complete", "step_cap") for doc in final.values()), {
        rid: doc["status"] for rid, doc in final.items()
    }
    for rid, doc in final.items():
        # The same point as planned; the time scale may be lower: on a slow machine the sweep
        # slows its runs down (testbed.sweep.runner), which changes how fast, not what is run.
        want = {k: v for k, v in plan[rid].items() if k != "time_scale"}
        assert {k: doc["config"][k] for k in want} == want
        assert doc["config"]["time_scale"] <= plan[rid]["time_scale"]
    # finished runs were not redone
    for rid, mtime in done_before.items():
        assert (out / "runs" / rid / "result.json").stat().st_mtime_ns == mtime


PROTOCOLS_SHORT = REPO / "testbed" / "experiments" / "protocols-short.toml"


@pytest.mark.skipif(
    shutil.which("batmand") is None,
    reason="batmand (package batmand) is not installed; some distributions do not have it",
)
def test_protocols_short_sweep_fills_the_protocols_section(tmp_path):
    """AODV, babel, batman and the oracle on the same seeds, on the empty and the office map
    (line of sight): the report compares them, and each protocol's control traffic in the
    captures is what it should be (AODV's equals its daemons' counts; the oracle sends none)."""
    out = tmp_path / "protocols"
    r = run_testbed("sweep", PROTOCOLS_SHORT, "--out", out)
    assert r.returncode == 0, r.stderr[-2000:]
    report_all(out)
    res = results(out)
    assert len(res) == 8 and all(d["status"] in ("complete", "step_cap") for d in res.values())
    rows = json.loads((out / "figures" / "protocols.json").read_text())
    by = {(row["map"], row["routing"]): row for row in rows}
    assert set(by) == {(m, p) for m in ("empty", "office") for p in
                       ("aodv", "babel", "batman", "oracle")}  # fmt: skip
    for m in ("empty", "office"):
        assert by[(m, "oracle")]["control_pkts_per_robot_s"] == 0
        for p in ("aodv", "babel", "batman"):
            assert by[(m, p)]["control_pkts_per_robot_s"] > 0, (m, p)
            # Packets flow; how many arrive is the protocol's and the walls' (one run a point:
            # batman delivered 0.48 of them on the office map in one Debian 13 run).
            assert by[(m, p)]["steps"] > 0 and by[(m, p)]["pdf"] > 0.25, (m, p)
        assert by[(m, "aodv")]["discovery_ms"] is not None
        assert by[(m, "babel")]["discovery_ms"] is None  # proactive: no discoveries
    text = (out / "report.md").read_text()
    assert "## Routing protocols against the oracle" in text
    assert "Does the paper's choice hold?" in text
    assert "batman" in text and "cannot be checked" in text
    per_run = json.loads((out / "figures" / "routing_runs.json").read_text())
    aodv = [row for row in per_run if row["daemon_relative_difference"] is not None]
    assert aodv and all(row["daemon_relative_difference"] <= 0.01 for row in aodv)
