"""The C++ robot's memory and thread safety, checked: `make build/asan/tb-robot` (Address
and UndefinedBehavior sanitizers) and `make build/tsan/tb-robot` (ThreadSanitizer), each run
as the whole team of a short run (three robots, 20 m radio, AODV, 400 steps at time scale 2:
floods relayed, goals sent and conflicts settled, the inbox, the planner and the timer all
busy; the display runs the same build). Clean means: no sanitizer report in any robot's log
or the display's, every robot exited by itself with status 0 (tb-robot's summary written)
and its frames answered, and the display's summary was written. Skipped where the C++
robot cannot be built (no g++ or libnng-dev)."""

import json
import subprocess
import uuid
from pathlib import Path

import pytest

from node.native import BINARY_ENV, unbuilt_reason
from testbed.run.execute import RunConfig, run
from testbed.run.robotchoice import carried_middlewares
from topology.network import destroy

REPO = Path(__file__).resolve().parents[2]
REPORTS = ("ERROR: AddressSanitizer", "ERROR: LeakSanitizer", "runtime error:",
           "WARNING: ThreadSanitizer", "SUMMARY: ")  # fmt: skip

# Skipped where make setup could not build the C++ robot (its one line says why: no g++ or
# libnng-dev, or g++ failed); where it built it, the sanitized builds must build and run clean.
pytestmark = pytest.mark.skipif(unbuilt_reason() is not None, reason=str(unbuilt_reason()))


@pytest.mark.slow
@pytest.mark.parametrize("middleware", ["nanomsg", "zeromq"])
@pytest.mark.parametrize("build", ["asan", "tsan"])
def test_a_team_of_sanitized_cpp_robots_runs_clean(tmp_path, monkeypatch, build, middleware):
    if middleware not in carried_middlewares():
        pytest.skip(f"build/tb-robot carries {' '.join(carried_middlewares())} only")
    target = f"build/{build}/tb-robot"
    subprocess.run(["make", "-s", target], cwd=REPO, check=True, timeout=900)
    monkeypatch.setenv(BINARY_ENV, str(REPO / target))
    # Reports to the robot's log (stderr); leaks reported at exit; TSan's exit status 66 on
    # a report, which the run records as the robot's.
    monkeypatch.setenv("ASAN_OPTIONS", "detect_leaks=1:abort_on_error=0")
    monkeypatch.setenv("UBSAN_OPTIONS", "print_stacktrace=1")
    tsan = "second_deadlock_stack=1"
    if middleware == "zeromq":  # libzmq is not instrumented: see the file
        tsan += f":suppressions={Path(__file__).with_name('tsan-libzmq.supp')}"
    monkeypatch.setenv("TSAN_OPTIONS", tsan)
    name = "ts" + uuid.uuid4().hex[:6]
    out = str(tmp_path / "run")
    cfg = RunConfig(robots=3, comm_range=20.0, laser_range=2.0, seed=3, time_scale=2.0,
                    max_steps=400, robot="cpp", middleware=middleware)  # fmt: skip
    try:
        result = run(cfg, out, name, progress=False).to_json()
    finally:
        destroy(name)
    assert result["robot"] == "cpp"
    for k in (1, 2, 3):
        log = (Path(out) / "robots" / f"r{k}.log").read_text()
        found = [line for line in log.splitlines() if any(r in line for r in REPORTS)]
        assert not found, f"r{k} under {build}:\n" + "\n".join(found[:20])
        assert f"robot up (C++, {REPO / target})" in log  # the sanitized build ran
        r = result["robots"][f"r{k}"]
        assert r["exit_status"] == 0, (k, r.get("exit_status"), log[-2000:])
    assert result["steps"] > 100
    # The display ran the same build (its part while the robots stepped) and ended in order.
    log = (Path(out) / "display" / "display.log").read_text()
    found = [line for line in log.splitlines() if any(r in line for r in REPORTS)]
    assert not found, f"the display under {build}:\n" + "\n".join(found[:20])
    assert f"display up (C++, {REPO / target})" in log
    events = (Path(out) / "display" / "events.jsonl").read_text().splitlines()
    assert json.loads(events[-1])["e"] == "summary", log[-2000:]
    for k in (1, 2, 3):  # each robot's own account of what carried its goals
        summary = json.loads((Path(out) / "robots" / f"r{k}.json").read_text())
        assert summary["middleware"] == middleware and summary["messenger"]["sent"] > 0, k
