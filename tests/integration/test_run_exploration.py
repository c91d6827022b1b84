"""Whole runs: robots explore the empty 20 x 20 m terrain over the emulated network.

Each run is real: one namespace and one process per robot, babel routing (AODV in one test),
the world's step clock at a raised time scale. Checked: the run stops by itself with >= 99% of
the free space covered, writes the run-results contract, and no robot ever received a map or a
goal from a robot it had no (time-respecting, multi-hop) path to; with 20 m every robot hears
every other."""

import csv
import json
import os
import time
import uuid

import pytest

from testbed.analysis import runcheck
from testbed.run.execute import RunConfig, run
from topology.network import destroy


@pytest.fixture
def tn_name():
    name = "tn" + uuid.uuid4().hex[:6]
    yield name
    destroy(name)


CONTRACT_FILES = [
    "result.json", "config.json", "links.csv", "coverage.csv", "positions.csv", "paths.png",
]  # fmt: skip


def check_contract(out: str, result: dict, robots: int) -> None:
    for f in CONTRACT_FILES:
        assert os.path.exists(os.path.join(out, f)), f
    for k in range(1, robots + 1):
        assert os.path.exists(os.path.join(out, "robots", f"r{k}.json"))
        assert os.path.exists(os.path.join(out, "robots", f"r{k}.log"))
    assert any(f.startswith("run.") for f in os.listdir(os.path.join(out, "display")))
    assert any(f.startswith("step-") for f in os.listdir(os.path.join(out, "display")))
    with open(os.path.join(out, "result.json")) as f:
        assert json.load(f) == result
    with open(os.path.join(out, "config.json")) as f:
        cfg = json.load(f)
    assert {k: cfg[k] for k in result["config"] if k != "extra"} == {
        k: v for k, v in result["config"].items() if k != "extra"
    }
    assert result["format"] == 1
    with open(os.path.join(out, "positions.csv")) as f:
        rows = list(csv.reader(f))
    assert len(rows[0]) == 1 + 2 * robots and rows[1][0] == "0"
    assert int(rows[-1][0]) == result["steps"] and len(rows) == result["steps"] + 2
    for r in result["robots"].values():
        assert r["plans"][0]["cause"] == "start"
        assert {p["cause"] for p in r["plans"]} <= {"start", "timer", "request"}
        assert r["messages"]["sent"].get("map", 0) > 0


def explore(tmp_path, name, robots, comm_range, time_scale=10.0, routing="babel", **kw):
    out = str(tmp_path / "run")
    cfg = RunConfig(
        robots=robots, comm_range=comm_range, laser_range=2.0, seed=robots * 7 + 1,
        time_scale=time_scale, routing=routing, max_steps=6000, **kw,
    )  # fmt: skip
    return out, run(cfg, out, name, progress=False).to_json()


def check_exploration(out: str, result: dict, robots: int, comm_range: float) -> None:
    assert result["status"] == "complete", result["status_detail"]
    assert result["coverage_final"] >= 0.99
    assert all(r["finish_step"] is not None for r in result["robots"].values())
    check_contract(out, result, robots)
    checked, bad = runcheck.causality_violations(out)
    assert not bad, f"{len(bad)} of {checked} messages had no path from their sender: {bad[:3]}"
    if robots > 1:
        assert checked > 0
    if comm_range >= 20:
        heard = runcheck.heard_from(out, robots)
        for k in range(1, robots + 1):
            assert heard[k] == set(range(1, robots + 1)) - {k}, f"r{k} heard only {heard[k]}"
        # The display knows the map only from the robots' local-map floods: what they flood
        # must be what they saw.
        assert result["display"]["coverage_final"] >= 0.95 * result["coverage_final"]


@pytest.mark.parametrize("robots", [1, 3])
@pytest.mark.parametrize("comm_range", [20.0, 5.0])
def test_team_explores_the_empty_terrain(tmp_path, tn_name, robots, comm_range):
    out, result = explore(tmp_path, tn_name, robots, comm_range)
    check_exploration(out, result, robots, comm_range)


def test_three_robots_explore_over_aodv_and_hear_only_along_paths(tmp_path, tn_name):
    """The same run over the AODV daemon (the paper's sweep's routing) instead of babel: 5 m
    range, so the goals' TCP needs routes found on demand, often over several hops."""
    out, result = explore(tmp_path, tn_name, 3, 5.0, routing="aodv")
    check_exploration(out, result, 3, 5.0)
    assert all(os.path.exists(os.path.join(out, "aodv", f"r{k}.json")) for k in (1, 2, 3))


@pytest.mark.parametrize(("coordination", "start"), [("paper", "spread"), ("paper", "corner")])
def test_paper_coordination_explores_to_the_end(tmp_path, tn_name, coordination, start):
    """The paper's rules read literally (node.coordination): robots with no admissible goal
    wait instead of taking a fallback, and every request forces a re-plan. The team must
    still finish by itself, and the run must record how it was coordinated and placed."""
    out, result = explore(tmp_path, tn_name, 4, 20.0, coordination=coordination, start=start)
    check_exploration(out, result, 4, 20.0)
    assert (result["config"]["coordination"], result["config"]["start"]) == (coordination, start)
    with open(os.path.join(out, "config.json")) as f:
        cfg = json.load(f)
    assert (cfg["coordination"], cfg["start"]) == (coordination, start)
    for k in range(1, 5):  # the paper's rules never send a robot to a frontier near a goal
        with open(os.path.join(out, "robots", f"r{k}.json")) as f:
            statuses = {p["status"] for p in json.load(f)["plan_details"]}
        assert "fallback" not in statuses and statuses <= {"ok", "blocked", "done"}
    if start == "spread":  # spread over the map, not clustered: some pair starts far apart
        xy = cfg["starts"]
        assert max(abs(a[0] - b[0]) + abs(a[1] - b[1]) for a in xy for b in xy) > 5.0


@pytest.mark.slow
@pytest.mark.parametrize("comm_range", [20.0, 5.0])
def test_ten_robots_explore_the_empty_terrain(tmp_path, tn_name, comm_range):
    out, result = explore(tmp_path, tn_name, 10, comm_range, time_scale=4.0)
    check_exploration(out, result, 10, comm_range)


def test_png_map_with_walls_and_a_door(tmp_path, tn_name):
    import cv2
    import numpy as np

    img = np.full((100, 150), 255, dtype=np.uint8)  # 0.1 m pixels: 15 x 10 m
    img[:, 70:72] = 0
    img[40:55, 70:72] = 255  # a 1.5 m door
    img[60:62, 0:50] = 0
    img[20:25, 100:130] = 0
    png = tmp_path / "office.png"
    cv2.imwrite(str(png), img)
    out, result = explore(tmp_path, tn_name, 2, 8.0, map=str(png), map_cell=0.1)
    assert result["status"] == "complete", result["status_detail"]
    assert result["coverage_final"] >= 0.99
    with open(os.path.join(out, "config.json")) as f:
        assert json.load(f)["map_size"] == [200, 300]
    with open(os.path.join(out, "map.png"), "rb") as f:  # the replay's picture, kept with it
        assert f.read() == png.read_bytes()


def test_live_view_streams_the_run_as_it_happens(tmp_path, tn_name):
    """--view: a browser's stream gets the robots and the link changes while the run goes on,
    and the run ends as it would have without it."""
    import socket
    import threading
    import urllib.request

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out = str(tmp_path / "live")
    cfg = RunConfig(robots=3, comm_range=5.0, laser_range=2.0, seed=5, time_scale=10.0,
                    routing="oracle", max_steps=1500, view=f"127.0.0.1:{port}")  # fmt: skip
    box = {}
    worker = threading.Thread(
        target=lambda: box.update(r=run(cfg, out, tn_name, progress=False).to_json())
    )
    worker.start()
    frames = []
    deadline = time.monotonic() + 60
    while not frames and time.monotonic() < deadline:
        try:
            stream = urllib.request.urlopen(f"http://127.0.0.1:{port}/api/live", timeout=10)
        except OSError:
            time.sleep(0.2)
            continue
        for line in stream:
            if line.startswith(b"data: "):
                frames.append(json.loads(line[6:]))
            if frames and frames[-1]["ended"]:
                break
    worker.join(timeout=120)
    result = box["r"]
    assert len(frames) > 10
    assert all(len(f["positions"]) == 6 for f in frames)
    assert len({tuple(map(tuple, f["links"])) for f in frames}) > 1  # links switched
    assert frames[-1]["ended"]
    assert result["status"] == "complete", result["status_detail"]
