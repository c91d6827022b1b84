"""Faults a run makes on purpose, in real runs: a robot stopped mid-run (`--kill`, a battery
failure) and a robot's radio out of everyone's range for a window of steps (`--isolate`, a
partition); and one it does not: a robot killed from outside. Three robots on a 10 x 10 m
empty map (about 200 steps), each run a few seconds.

Checked: the stopped robot is no crash (the run completes when the others finish) and is
left out of mean_finish_step; the isolated robot's links are down in the topology record
for exactly its window, nobody hears it or is heard by it then (the robots' own receipts),
and the team still finishes; the robot killed from outside is a crash, at its step.
"""

import contextlib
import csv
import json
import os
import signal
import statistics
import threading
import uuid

import pytest

from testbed.analysis import runcheck
from testbed.files.isolation import Outage
from testbed.run.execute import RunConfig, run
from topology.network import destroy


@pytest.fixture
def fal_name():
    name = "fal" + uuid.uuid4().hex[:6]
    yield name
    destroy(name)


def small_run(tmp_path, name, small_map, **kw):
    out = str(tmp_path / "run")
    cfg = RunConfig(
        robots=3, comm_range=20.0, laser_range=2.0, seed=22, time_scale=10.0,
        routing="babel", max_steps=1500, map=small_map, map_cell=0.1, **kw,
    )  # fmt: skip
    return out, run(cfg, out, name, progress=False).to_json()


def events(out: str) -> list[dict]:
    with open(f"{out}/events.jsonl") as f:
        return [json.loads(line) for line in f]


def test_a_robot_stopped_mid_run_is_no_crash_and_no_part_of_the_mean(tmp_path, fal_name, small_map):
    out, result = small_run(tmp_path, fal_name, small_map, kill=((2, 60),))
    assert result["status"] == "complete", result["status_detail"]
    assert "r2 stopped at step 60" in result["status_detail"]
    r = result["robots"]
    assert r["r2"]["stopped_step"] == 60 and not r["r2"]["crashed"]
    assert r["r2"]["finish_step"] is None and r["r2"]["exit_status"] == -9
    for k in ("r1", "r3"):
        assert r[k]["stopped_step"] is None and not r[k]["crashed"]
        assert r[k]["finish_step"] is not None and r[k]["exit_status"] == 0
    assert result["survivors_finished"] is True
    assert result["mean_finish_step_robots"] == 2
    survivors = statistics.fmean([r["r1"]["finish_step"], r["r3"]["finish_step"]])
    assert result["mean_finish_step"] == pytest.approx(survivors, abs=0.01)
    assert result["coverage_final"] >= 0.99
    assert events(out) == [{"step": 60, "e": "stopped", "robot": "r2"}]
    with open(f"{out}/robots/r2.json") as f:
        assert json.load(f)["stopped_step"] == 60


def test_an_isolated_robot_is_cut_off_for_its_window_and_the_team_finishes(
    tmp_path, fal_name, small_map
):
    window = Outage(3, 60, 60)  # out at steps 60..119, back at 120
    out, result = small_run(tmp_path, fal_name, small_map, isolate=(window,))
    assert result["status"] == "complete", result["status_detail"]
    assert result["steps"] > window.end + 20  # the run went on well past the window
    assert all(r["finish_step"] is not None for r in result["robots"].values())
    assert result["isolated"] == [{"robot": "r3", "from_step": 60, "back_step": 120}]
    assert events(out) == [
        {"step": 60, "e": "isolated", "robot": "r3"},
        {"step": 120, "e": "back_in_range", "robot": "r3"},
    ]
    # links.csv: within 20 m on a 10 m map every pair is linked, but r3's links (to r1, r2
    # and the display r4) go at step 60 and come back at 120, and only then.
    with open(f"{out}/links.csv") as f:
        rows = [(int(s), e, int(i), int(j)) for s, e, i, j in list(csv.reader(f))[1:]]
    of3 = [row for row in rows if 3 in row[2:] and row[0] > 0]
    assert sorted(of3) == [
        (60, "remove", 1, 3), (60, "remove", 2, 3), (60, "remove", 3, 4),
        (120, "add", 1, 3), (120, "add", 2, 3), (120, "add", 3, 4),
    ]  # fmt: skip
    # The robots' own receipts: nothing crossed to or from r3 in the window (two steps of
    # slack for what was in flight), and it heard its teammates before and after.
    got = runcheck.received(out, 3)
    inside = [e for e in got if window.start + 2 <= e["step"] < window.end - 2]
    assert not [e for e in inside if 3 in (e["to"], e["frm"])]
    assert [e for e in inside if {e["to"], e["frm"]} == {1, 2}]  # the others still talk
    to3 = [e["step"] for e in got if e["to"] == 3 and e["frm"] in (1, 2)]
    assert min(to3) < window.start and max(to3) >= window.end
    checked, bad = runcheck.causality_violations(out)
    assert checked > 0 and not bad


def _kill_when_running(robot: int, marks: tuple[str, ...], stop: threading.Event) -> None:
    """SIGKILL robot `robot`'s process (its comm is "rK robot", its command line names the
    run) half a second after it appears: a crash the run did not ask for."""
    while not stop.wait(0.05):
        for pid in filter(str.isdigit, os.listdir("/proc")):
            try:
                with open(f"/proc/{pid}/comm") as f:
                    comm = f.read().strip()
                with open(f"/proc/{pid}/cmdline", "rb") as f:
                    cmdline = f.read().decode(errors="replace")
            except OSError:
                continue
            if comm == f"r{robot} robot" and any(m in cmdline for m in marks):
                stop.wait(0.5)
                with contextlib.suppress(ProcessLookupError):
                    os.kill(int(pid), signal.SIGKILL)
                return


def test_a_robot_that_dies_unasked_is_a_crash_noticed_at_its_step(tmp_path, fal_name, small_map):
    """The step loop looks for exited robots once a step (one look at the fork server's exit
    reports for all of them): a robot killed from outside is recorded as crashed, at the
    step it was noticed, and the run says so; the others still finish."""
    stop = threading.Event()
    killer = threading.Thread(
        target=_kill_when_running, args=(2, (fal_name, str(tmp_path)), stop), daemon=True
    )
    killer.start()
    try:
        out, result = small_run(tmp_path, fal_name, small_map)
    finally:
        stop.set()
        killer.join()
    assert result["status"] == "robot_crashed", result["status_detail"]
    r = result["robots"]
    assert r["r2"]["crashed"] and r["r2"]["exit_status"] == -9
    with open(f"{out}/robots/r2.json") as f:
        step = json.load(f)["crash_step"]
    assert result["status_detail"] == f"r2 exited with status -9 at step {step}"
    assert 0 < step < result["steps"]
    for k in ("r1", "r3"):
        assert not r[k]["crashed"] and r[k]["finish_step"] is not None
