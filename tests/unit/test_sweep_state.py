"""sweep.json's type (testbed.files.sweepstate): what the runner writes reads back the same,
old files get their defaults, and a malformed file is refused naming the field."""

import json

import pytest

from common.errors import UsageError
from testbed.files import sweepstate
from testbed.files.sweepstate import SweepRun, SweepState

WRITTEN = {
    "format": 1,
    "sweep_file": "testbed/experiments/x.toml",
    "spec": {"grid": {"robots": [2, 3]}, "run": {"comm_range": 20, "routing": "aodv"},
             "runs": 2, "time_scale_by_robots": {"2": 0.5}},
    "jobs_requested": 2, "jobs": 1, "load_limit_requested": None, "load_limit": None,
    "cpu_limit_requested": 1.5, "cpu_limit": 1.2, "time_scale_factor": {"2": 0.8},
    "netem": True,
    "calibration": {"2": {"factor": 0.8, "trials": [[1.0, 0.2, False], [0.8, 0.0, True]]}},
    "backoffs": [{"run": "a", "jobs": 1}],
    "updated": "2026-11-27T10:00:00+0000",
    "runs": [
        {"id": "n02-a", "index": 0, "config": {"robots": 2, "comm_range": 20.0},
         "status": "done", "attempts": 1, "pid": 12, "pid_start": 99, "wall_time_s": 3.5},
        {"id": "n03-a", "index": 1, "config": {"robots": 3, "comm_range": 20.0},
         "status": "pending"},
    ],
}  # fmt: skip


def test_what_the_runner_writes_reads_back_byte_for_byte(tmp_path):
    state = SweepState.from_dict(json.loads(json.dumps(WRITTEN)))
    assert state.to_dict() == WRITTEN
    assert list(state.to_dict()) == list(WRITTEN)  # the keys in the file's order
    assert list(state.runs[0].to_dict()) == list(WRITTEN["runs"][0])
    sweepstate.write(tmp_path, state)
    text = (tmp_path / "sweep.json").read_text()
    assert text == json.dumps(WRITTEN, indent=1) + "\n"
    assert sweepstate.read(tmp_path) == state


def test_the_fields_readers_use():
    state = SweepState.from_dict(WRITTEN)
    run = state.run("n02-a")
    assert run is not None and run.status == "done" and run.pid == 12 and run.pid_start == 99
    assert state.run("nope") is None
    assert state.spec_value("robots") == [2, 3]
    assert state.spec_value("comm_range") == 20 and state.spec_value("comm_range", True) == [20]


def test_an_old_file_gets_its_defaults():
    state = SweepState.from_dict({"spec": {"robots": [2], "routing": "aodv"}})
    assert state.runs == () and state.sweep_file is None and state.backoffs == ()
    assert dict(state.calibration) == {} and dict(state.time_scale_factor) == {}
    # before grids: every field at the spec's top level
    assert state.spec_value("robots", listed=True) == [2]
    assert SweepState.from_dict({}).spec == {}
    run = SweepState.from_dict({"runs": [{"id": "a"}]}).runs[0]
    assert run == SweepRun(id="a") and run.status is None and run.to_dict() == {"id": "a"}


def test_the_scalars_are_typed():
    state = SweepState.from_dict(WRITTEN)
    assert (state.jobs_requested, state.jobs, state.netem) == (2, 1, True)
    assert (state.load_limit_requested, state.load_limit) == (None, None)
    assert (state.cpu_limit_requested, state.cpu_limit) == (1.5, 1.2)
    old = SweepState.from_dict({})
    assert (old.jobs, old.load_limit, old.cpu_limit, old.netem, old.updated) == (None,) * 5
    whole = SweepState.from_dict({"load_limit": 60, "cpu_limit_requested": 2})
    assert whole.to_dict()["load_limit"] == 60  # an int stays an int: the same bytes


def test_no_file_is_none(tmp_path):
    assert sweepstate.read(tmp_path) is None


@pytest.mark.parametrize(
    ("doc", "field"),
    [
        ([], "not a JSON object"),
        ({"runs": {}}, "runs is not a list"),
        ({"runs": [{"id": "../x"}]}, "runs[0].id"),
        ({"runs": [{"id": "a", "pid": -1}]}, "runs[0].pid"),
        ({"backoffs": [1]}, "backoffs"),
        ({"calibration": {"2": 1}}, "calibration"),
        ({"time_scale_factor": {"x": 1}}, "time_scale_factor"),
        ({"spec": {"grid": []}}, "spec.grid"),
        ({"jobs": "auto"}, "jobs"),
        ({"jobs_requested": 1.5}, "jobs_requested"),
        ({"format": True}, "format"),
        ({"load_limit": 0}, "load_limit"),
        ({"cpu_limit_requested": "2"}, "cpu_limit_requested"),
        ({"cpu_limit": [1]}, "cpu_limit"),
        ({"netem": 1}, "netem"),
        ({"updated": 5}, "updated"),
    ],
)
def test_a_malformed_file_is_refused_naming_the_field(tmp_path, doc, field):
    with pytest.raises(ValueError) as e:
        SweepState.from_dict(doc)
    assert field in str(e.value)
    (tmp_path / "sweep.json").write_text(json.dumps(doc))
    with pytest.raises(UsageError) as u:
        sweepstate.read(tmp_path)
    assert "sweep.json" in str(u.value) and field in str(u.value) and "\n" not in str(u.value)
