"""Both robot programs leave the same robots/rK.json: a lone robot's short run (seed 1, time
scale 5, 150 steps) with `--robot python` and with `--robot cpp`, and each run's robot record
must have the same keys, nested ones too, with values of the same JSON types; the summary
event it was made of (the last of robots/r1.events.jsonl) must have node.summary's keys in
their order and types. Counters (messages by kind, ...) name only what happened, so there a
key one robot lacks is no difference (tests/unit/test_robot_summary_keys.py's rules). The
C++ case is skipped where build/tb-robot was not built."""

import json
import os
import uuid

import pytest

from node import summary
from node.native import unbuilt_reason
from testbed.run.execute import RunConfig, run
from tests.unit.test_robot_summary_keys import fields_of, key_differences, type_differences
from topology.network import destroy

pytestmark = pytest.mark.skipif(unbuilt_reason() is not None, reason=str(unbuilt_reason()))


def lone_run(tmp_path, robot: str) -> tuple[dict, dict]:
    """(robots/r1.json, its summary event) of a short lone run with this robot program."""
    name = "ts" + uuid.uuid4().hex[:6]
    out = str(tmp_path / robot)
    cfg = RunConfig(robots=1, comm_range=20.0, laser_range=2.0, seed=1, time_scale=5.0,
                    max_steps=150, robot=robot)  # fmt: skip
    try:
        result = run(cfg, out, name, progress=False).to_json()
    finally:
        destroy(name)
    assert result["robot"] == robot, result["robot_reason"]
    with open(os.path.join(out, "robots", "r1.json")) as f:
        record = json.load(f)
    with open(os.path.join(out, "robots", "r1.events.jsonl")) as f:
        events = [json.loads(line) for line in f]
    assert events[-1]["e"] == "summary"
    return record, events[-1]


@pytest.mark.slow
def test_both_robots_write_the_same_robot_record(tmp_path):
    py_record, py_summary = lone_run(tmp_path, "python")
    cc_record, cc_summary = lone_run(tmp_path, "cpp")
    assert py_summary["robot_impl"] == "python" and cc_summary["robot_impl"] == "cpp"
    assert summary.problems(fields_of(py_summary)) == []
    assert summary.problems(fields_of(cc_summary)) == []
    assert list(py_record) == list(cc_record)  # the same keys in the same order
    assert key_differences(py_record, cc_record) == []
    assert type_differences(py_record, cc_record) == []
