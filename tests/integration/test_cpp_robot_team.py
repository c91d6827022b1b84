"""A mixed team (docs/robot-contract.md): Python robots and a C++ robot explore together
and finish. Three robots on the empty terrain, 20 m radio, AODV: r1 and r2 are the Python
robot, r3 the C++ robot (build/tb-robot). Each kind must hear the other's maps and goals and
the run must end by itself with every robot finished; the C++ robot's rK.json says it is
the C++ one. Over each middleware the C++ robot carries: nanomsg (nng on both sides) and
ZeroMQ (pyzmq against libzmq's C API). Skipped where build/tb-robot was not built, and the
ZeroMQ case where it was built without libzmq."""

import json
import os
import uuid

import pytest

from node.native import unbuilt_reason
from testbed.run.execute import RunConfig, run
from testbed.run.robotchoice import carried_middlewares
from topology.network import destroy

pytestmark = pytest.mark.skipif(unbuilt_reason() is not None, reason=str(unbuilt_reason()))


def robot_summary(out: str, k: int) -> dict:
    with open(os.path.join(out, "robots", f"r{k}.events.jsonl")) as f:
        events = [json.loads(line) for line in f]
    return next(e for e in reversed(events) if e["e"] == "summary")


@pytest.mark.parametrize("middleware", ["nanomsg", "zeromq"])
def test_python_and_cpp_robots_explore_together_and_finish(tmp_path, middleware):
    if middleware not in carried_middlewares():
        pytest.skip(f"build/tb-robot carries {' '.join(carried_middlewares())} only")
    name = "tc" + uuid.uuid4().hex[:6]
    out = str(tmp_path / "run")
    cfg = RunConfig(robots=3, comm_range=20.0, laser_range=2.0, seed=7, time_scale=5.0,
                    max_steps=2500, middleware=middleware)  # fmt: skip
    try:
        result = run(cfg, out, name, progress=False, cpp_robots=frozenset({3})).to_json()
    finally:
        destroy(name)
    assert result["robot"] == "mixed" and "r3" in result["robot_reason"]
    assert result["status"] == "complete", result["status_detail"]
    assert result["survivors_finished"] and result["coverage_final"] >= 0.95
    kinds = {k: robot_summary(out, k).get("robot_impl", "python") for k in (1, 2, 3)}
    assert kinds == {1: "python", 2: "python", 3: "cpp"}
    for k in (1, 2, 3):
        s = robot_summary(out, k)
        assert s["middleware"] == middleware, (k, s["middleware"])
        assert s["finished"], f"r{k} did not finish"
        assert s["malformed"] == 0, f"r{k} refused messages of the other kind"
        frm = s["maps"]["received_from"]
        assert {f"r{j}" for j in (1, 2, 3) if j != k} <= set(frm), (k, frm)
        assert s["received"].get("goal", 0) > 0, f"r{k} heard no goal"
    # The C++ robot's goals reached the Python robots and theirs reached it (events).
    for k in (1, 2):
        with open(os.path.join(out, "robots", f"r{k}.events.jsonl")) as f:
            recv = [json.loads(line) for line in f if '"recv"' in line]
        assert any(e["kind"] == "goal" and e["frm"] == 3 for e in recv), f"r{k}: no goal of r3"
    with open(os.path.join(out, "robots", "r3.events.jsonl")) as f:
        recv = [json.loads(line) for line in f if '"recv"' in line]
    assert {e["frm"] for e in recv if e["kind"] == "goal"} == {1, 2}
