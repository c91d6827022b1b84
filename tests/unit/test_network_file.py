"""A `net up --capture` network's network.json (testbed.files.networkfile): what topology.bringup
writes reads back; a file that is not one (truncated, wrong types, a routing or time scale out
of range) is one line of ResultError naming the file and the key, which `testbed metrics`
reports as one line, exit 2 (tests/unit/test_hostile_inputs.py)."""

import json

import pytest

from testbed.files import networkfile
from testbed.files.networkfile import NetworkRecord, ResultError


def write(tmp_path, doc) -> str:
    path = networkfile.network_path(tmp_path)
    (tmp_path / "daemons").mkdir(exist_ok=True)
    with open(path, "w") as f:
        f.write(doc if isinstance(doc, str) else json.dumps(doc))
    return path


def test_what_net_up_writes_reads_back(tmp_path):
    from topology import state
    from topology.spec import NetworkSpec

    spec = NetworkSpec("t", ((0.0, 0.0), (1.0, 0.0)), 10.0, routing="babel", time_scale=5.0)
    path = write(tmp_path, state.spec_to_dict(spec))
    assert networkfile.read(path) == NetworkRecord(routing="babel", time_scale=5.0)


def test_none_when_missing_and_defaults_when_silent(tmp_path):
    assert networkfile.read(networkfile.network_path(tmp_path)) is None
    assert networkfile.read(write(tmp_path, {})) == NetworkRecord("aodv", None)


@pytest.mark.parametrize(
    ("doc", "words"),
    [
        ('{"routing": "aodv", "time_', "not valid JSON"),  # truncated
        ("[1]", "not a JSON object"),
        ({"routing": 3}, "'routing' is int, not str"),
        ({"routing": "ospf"}, "'routing' is not one of"),
        ({"time_scale": "fast"}, "'time_scale' is str"),
        ({"time_scale": True}, "'time_scale' is bool"),
        ({"time_scale": -1}, "'time_scale'"),
        ({"time_scale": 1e308}, "'time_scale'"),
    ],
)
def test_a_bad_file_is_one_line_naming_it(tmp_path, doc, words):
    path = write(tmp_path, doc)
    with pytest.raises(ResultError) as e:
        networkfile.read(path)
    text = str(e.value)
    assert "\n" not in text and text.startswith(f"{path}: ") and words in text
