"""The one-per-idea helpers every package uses: number arguments, atomic JSON files, the
routing daemons' files (the packages' independence: test_layers.py)."""

import argparse
import json
import os

import pytest

from common import jsonfile
from common.argtypes import checked, number
from topology.routing import keep_daemon_files

# -- number arguments -------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kind", "kw", "text", "value"),
    [
        (int, {"minimum": 1}, "1", 1),
        (float, {"above": 0}, "0.5", 0.5),
        (float, {"minimum": 0}, "0", 0.0),
        (float, {}, "-3.25", -3.25),
    ],
)
def test_number_accepts_values_in_range(kind, kw, text, value):
    got = number(kind, "x", **kw)(text)
    assert got == value and type(got) is kind


@pytest.mark.parametrize(
    ("kind", "kw", "text", "words"),
    [
        (int, {}, "two", "x must be a whole number, not 'two'"),
        (float, {}, "abc", "x must be a number, not 'abc'"),
        (float, {}, "nan", "x must be finite, not 'nan'"),
        (float, {}, "-inf", "x must be finite, not '-inf'"),
        (float, {"above": 0}, "0", "x must be greater than 0, not 0"),
        (int, {"minimum": 4}, "3", "x must be at least 4, not 3"),
        (float, {"minimum": 0}, "-1", "x must not be negative, not -1"),
        (int, {"minimum": 1}, "1.5", "x must be a whole number, not '1.5'"),
    ],
)
def test_number_rejects_with_one_line_naming_the_value(kind, kw, text, words):
    with pytest.raises(argparse.ArgumentTypeError) as e:
        number(kind, "x", **kw)(text)
    assert str(e.value) == words


# -- atomic JSON ------------------------------------------------------------------------------


def test_checked_prints_the_checks_own_reason_as_a_usage_error():
    def even(text: str) -> int:
        if int(text) % 2:
            raise ValueError(f"{text} is odd")
        return int(text)

    parse = checked(even)
    assert parse("4") == 4 and parse.__name__ == "even"
    with pytest.raises(argparse.ArgumentTypeError, match="^3 is odd$"):
        parse("3")
    with pytest.raises(argparse.ArgumentTypeError, match="invalid literal"):
        parse("x")  # int()'s own ValueError, its own words


def test_json_round_trip_and_format(tmp_path):
    path = tmp_path / "a.json"
    jsonfile.write_json_atomic(path, {"b": 1, "a": [1, 2]})
    assert path.read_text() == json.dumps({"b": 1, "a": [1, 2]}, indent=1) + "\n"
    assert jsonfile.read_json(path) == {"b": 1, "a": [1, 2]}
    jsonfile.write_json_atomic(path, {"b": 1, "a": 2}, sort_keys=True)
    assert path.read_text().index('"a"') < path.read_text().index('"b"')


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    path = tmp_path / "a.json"
    jsonfile.write_json_atomic(path, {"old": True})
    with pytest.raises(TypeError):
        jsonfile.write_json_atomic(path, {"new": object()})  # not serialisable: fails midway
    assert jsonfile.read_json(path) == {"old": True}
    assert os.listdir(tmp_path) == ["a.json"]


def test_missing_and_corrupt_files_read_as_none(tmp_path):
    assert jsonfile.read_json(tmp_path / "nothing.json") is None
    (tmp_path / "cut.json").write_text('{"a": [1, 2')
    assert jsonfile.read_json(tmp_path / "cut.json") is None


# -- the routing daemons' files ---------------------------------------------------------------


def test_daemon_files_go_to_the_run_layout(tmp_path):
    state = tmp_path / "state"
    state.mkdir()
    for k in (1, 2):
        (state / f"r{k}.aodv.log").write_text(f"log {k}\n")
    (state / "r1.aodv.json").write_text("{}\n")  # r2's daemon never wrote its statistics
    (state / "r1.tcpdump.log").write_text("not a daemon's\n")
    keep_daemon_files("aodv", [1, 2, 3], str(state), str(tmp_path / "routing"),
                      str(tmp_path / "aodv"))  # fmt: skip
    assert sorted(os.listdir(tmp_path / "routing")) == ["r1.aodv.log", "r2.aodv.log"]
    assert (tmp_path / "routing" / "r2.aodv.log").read_text() == "log 2\n"
    assert os.listdir(tmp_path / "aodv") == ["r1.json"]


def test_a_protocol_without_statistics_makes_no_statistics_folder(tmp_path):
    (tmp_path / "r1.babel.log").write_text("x\n")
    keep_daemon_files("babel", [1], str(tmp_path), str(tmp_path / "routing"),
                      str(tmp_path / "babel"))  # fmt: skip
    assert os.listdir(tmp_path / "routing") == ["r1.babel.log"]
    assert not (tmp_path / "babel").exists()


def test_topology_knows_the_aodv_profiles_aodv_defines():
    from aodv.params import PROFILES
    from topology.spec import AODV_PROFILES

    assert set(AODV_PROFILES) == set(PROFILES)


def test_aodv_daemons_get_their_profile_and_a_counter_file():
    from topology import routing
    from topology.spec import NetworkSpec

    spec = NetworkSpec("t1", ((0, 0), (5, 0)), 10, routing="aodv", aodv_profile="ns3")
    argv = routing.argv_for(spec, 2, "/run/x")
    assert argv[argv.index("--profile") + 1] == "ns3"
    assert argv[argv.index("--state") + 1] == "/run/x/r2.aodv.state"
    with pytest.raises(ValueError, match="unknown AODV profile"):
        NetworkSpec("t1", ((0, 0),), 10, aodv_profile="olsr")
