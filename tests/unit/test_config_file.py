"""A run's config.json as one type (testbed.files.configfile): what prepare writes reads back
the same, result.json's config comes from it, the view's fields are checked with old runs'
defaults, and a malformed file is refused naming the key."""

import json
import os

import pytest

from common import boundedfile
from testbed.files import configfile
from testbed.files.configfile import ConfigError, RunConfigFile
from testbed.files.runconfig import RunConfig


def _written(tmp_path):
    config = RunConfig(robots=3, comm_range=20.0, seed=4).to_dict()
    config.update(map_size=[200, 300], starts=[[1.0, 2.0]], display=4, display_pos=[5.0, 6.0],
                  name="t1", snapshots=[0, 10])  # fmt: skip
    return config, configfile.write(tmp_path, config)


def test_what_prepare_writes_reads_back_byte_for_byte(tmp_path):
    config, written = _written(tmp_path)
    text = (tmp_path / "config.json").read_text()
    assert text == json.dumps(config, indent=1) + "\n"
    back = configfile.read(tmp_path / "config.json")
    assert back == written and back.to_dict() == config and list(back.to_dict()) == list(config)
    rc = back.result_config()
    assert (rc.robots, rc.comm_range, rc.seed) == (3, 20.0, 4)
    assert rc.extra["starts"] == [[1.0, 2.0]]


def test_the_views_fields(tmp_path):
    _, written = _written(tmp_path)
    v = written.view()
    assert (v.robots, v.comm_range, v.map_cell, v.display) == (3, 20.0, 0.05, [5.0, 6.0])
    assert v.map_m == [300 * 0.05, 200 * 0.05]


def test_an_old_config_gets_its_defaults():
    v = RunConfigFile.from_dict({"robots": 2, "comm_range": 5}).view()
    assert v.map_m == [20.0, 20.0] and v.map_cell == 0.05 and v.display == [] and v.map is None


@pytest.mark.parametrize(
    ("doc", "says"),
    [
        ({"comm_range": 5}, "robots is not a number"),
        ({"robots": 2.5, "comm_range": 5}, "robots 2.5 is not a whole number"),
        ({"robots": 2, "comm_range": -1}, "comm_range -1 is not in"),
        ({"robots": 2, "comm_range": 5, "map_cell": 0}, "map_cell 0 is not in"),
        ({"robots": 2, "comm_range": 5, "map_size": [1]}, "map_size is not [rows, cols]"),
        ({"robots": 2, "comm_range": 5, "map_size": [1, True]}, "map_size is not a number"),
        ({"robots": 2, "comm_range": 5, "display_pos": [1, 2, 3]}, "display_pos is not [x, y]"),
    ],
)
def test_a_malformed_config_is_refused_naming_the_key(doc, says):
    with pytest.raises(ConfigError) as e:
        RunConfigFile.from_dict(doc).view()
    assert str(e.value).startswith(says)


def test_what_is_not_a_json_object_is_refused(tmp_path):
    for text in ("[]", "{", "1e400x"):
        (tmp_path / "c").write_text(text)
        with pytest.raises(ConfigError, match="not a JSON object"):
            configfile.read(tmp_path / "c")
    os.mkfifo(tmp_path / "fifo")
    with pytest.raises(boundedfile.Refused):
        configfile.read(tmp_path / "fifo")
