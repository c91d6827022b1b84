"""A lone robot is deterministic: at time scale 5 it takes exactly the steps and the path it
took before the per-step work was compiled and the timer woken only for work (seeds 1, 2, 3:
1901, 1989 and 1964 steps; tests/data/lone-k5 holds the positions.csv each run wrote then).

A run's answer is only exact when no plan came late and no plan timer fired late (a lone run
is deterministic, and one late plan may move its path: testbed.run.fidelity, "Decided"); the
fidelity verdict tolerates one plan in a hundred, so a faithful run is not enough. Nor does
it judge a "done" that reached the world after its step's deadline (the robot's finish is
its message's step; the world ran a step longer on the same path): `late_dones`. A run with
a late plan, timer or "done" is redone, up to three runs; at least one must be clean, and
every clean run must be exact. Every run's finish is the step its robot decided it at (its
events.jsonl's `finish`).

The world runs its default step loop (the compiled one where make setup built it:
tests/integration/test_step_loop_twin.py holds the Python reference loop to the same paths).
Both robot programs are held to it (`--robot python`, the reference, and `--robot cpp`, the
C++ robot of native/robot, which calls the same step core): one answer, two implementations.
Each runs its own display (the C++ one draws after the run what it kept: node.displayreplay),
and the display's merged map must be the one the Python display made of that path (its
map.npy's SHA-256, DISPLAY_MAPS). The C++ case is skipped where build/tb-robot was not built
(no g++ or libnng-dev)."""

import hashlib
import json
import os
import uuid

import numpy as np
import pytest

from node.native import unbuilt_reason
from testbed.run import steploop
from testbed.run.execute import RunConfig, run
from topology.network import destroy

DATA = os.path.join(os.path.dirname(__file__), "..", "data", "lone-k5")
STEPS = {1: 1901, 2: 1989, 3: 1964}
# The first 16 hex digits of the SHA-256 of display/map.npy's cells (the Python display's).
DISPLAY_MAPS = {1: "c542ebcdf164e5c5", 2: "d2142dcf0cc60cf1", 3: "26feac37e716b833"}


@pytest.mark.slow
@pytest.mark.parametrize("robot", ["python", "cpp"])
@pytest.mark.parametrize("seed", sorted(STEPS))
def test_lone_robot_takes_the_same_steps_and_path(tmp_path, seed, robot):
    if robot == "cpp" and unbuilt_reason() is not None:
        pytest.skip(str(unbuilt_reason()))
    with open(os.path.join(DATA, f"seed{seed}.positions.csv")) as f:
        expected = f.read()
    clean = 0
    for attempt in range(3):
        name = "tx" + uuid.uuid4().hex[:6]
        out = str(tmp_path / f"run{attempt}")
        cfg = RunConfig(robots=1, comm_range=20.0, laser_range=2.0, seed=seed, time_scale=5.0,
                        robot=robot)  # fmt: skip
        try:
            result = run(cfg, out, name, progress=False).to_json()
        finally:
            destroy(name)
        assert result["robot"] == robot, result["robot_reason"]
        assert result["step_loop"] == steploop.loop_kind()  # the default: compiled where built
        assert result["robots"]["r1"]["finish_step"] == _finish_decided(out)
        m = result["fidelity"]["measures"]
        if not result["fidelity"]["ok"] or m["late_plans"] or m["late_timers"] or m["late_dones"]:
            continue
        clean += 1
        assert result["steps"] == STEPS[seed], m
        with open(os.path.join(out, "positions.csv")) as f:
            assert f.read() == expected, "the path differs"
        cells = np.load(os.path.join(out, "display", "map.npy")).tobytes()
        assert hashlib.sha256(cells).hexdigest()[:16] == DISPLAY_MAPS[seed], "the display's map"
        break
    assert clean, "no run of three was without late plans at time scale 5"


def _finish_decided(out: str) -> int | None:
    """The step at which the robot decided it was done (its events.jsonl's `finish`)."""
    with open(os.path.join(out, "robots", "r1.events.jsonl")) as f:
        for line in f:
            e = json.loads(line)
            if e.get("e") == "finish":
                return e["step"]
    return None
