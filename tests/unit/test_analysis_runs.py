"""The analysis's one reader of result.json: typed values, defaults for old results, and
one clear line for a malformed file."""

import dataclasses
import json

import pytest

from testbed import sweepfile
from testbed.analysis.runs import ResultError, load_run, load_runs
from tests.unit.test_sweep_synthetic import result_doc, timer_plans, write_run


def one_run(tmp_path, **config):
    spec = sweepfile.SweepSpec(robots=(2,), comm_range=(5.0,), laser_range=(2.0,), runs=1)
    run = sweepfile.expand(spec)[0]
    c = dataclasses.replace(run.config, **config)
    return write_run(tmp_path, run, result_doc(c, [90, None], 100, {1: timer_plans(100, 2)}))


def test_a_result_is_read_into_typed_values(tmp_path):
    run = load_run(one_run(tmp_path))
    assert run.status == "complete" and run.usable and run.unimpaired
    assert (run.config.robots, run.config.comm_range, run.steps) == (2, 5.0, 100)
    assert [r.name for r in run.robots] == ["r1", "r2"]
    assert (run.robots[0].plans[1].step, run.robots[0].plans[1].cause) == (7, "request")
    assert run.robots[0].sent["map"] == 2
    assert run.exploration_steps == (90 + 100) / 2  # the unfinished robot counts the last step
    with pytest.raises(AttributeError):
        run.steps = 3  # frozen


def test_results_from_before_a_key_existed_get_its_default(tmp_path):
    d = one_run(tmp_path)
    doc = json.loads((d / "result.json").read_text())
    for key in ("coordination", "start", "routing", "map", "loss_pct", "delay_ms"):
        doc["config"].pop(key, None)
    (d / "result.json").write_text(json.dumps(doc))
    run = load_run(d)
    assert run.variant == ("ours", "corner")
    assert run.network == ("aodv", "empty")
    assert run.unimpaired


@pytest.mark.parametrize(
    "text, says",
    [
        ("{not json", "unreadable"),
        ("[]", "not a JSON object"),
        ('{"status": "complete"}', "no 'config'"),
        ('{"status": "complete", "config": {"robots": "two"}}', "'robots' is str, not int"),
        ('{"config": {"robots": 2, "comm_range": 5, "laser_range": 2}}', "no 'status'"),
    ],
)
def test_a_malformed_result_is_one_line_naming_the_file(tmp_path, text, says):
    d = tmp_path / "runs" / "r"
    d.mkdir(parents=True)
    (d / "result.json").write_text(text)
    with pytest.raises(ResultError) as e:
        load_run(d)
    assert str(d / "result.json") in str(e.value) and says in str(e.value)
    assert "\n" not in str(e.value)
    assert load_runs(tmp_path) == []  # a sweep's report leaves it out


def test_no_result_is_not_a_finished_run(tmp_path):
    with pytest.raises(ResultError, match="not a finished run"):
        load_run(tmp_path)
