"""medium.json's type (testbed.files.mediumfile): the channel's counters and its `relay_lag`
read back as written; a file that is not what the channel writes (truncated, wrong types,
counts out of range) is one line of ResultError naming the file and the key, and the run's
fidelity verdict (testbed.run.results.channel_relay_lag) then leaves the channel out."""

import json
import logging

import pytest

from testbed.files import mediumfile
from testbed.files.mediumfile import RelayLag, ResultError

GOOD = {
    "now_s": 12.5,
    "qos": False,
    "lateness": {"probes": 10, "max_ms": 0.5, "mean_ms": 0.1, "over_1ms": 0},
    "relay_lag": {"frames": 400, "max_ms": 3.0, "mean_ms": 0.2, "over_1ms": 4},
    "robots": [{"from_linux": 10, "to_linux": 9, "retries": 1, "airtime_s": 0.5}],
}


def write(tmp_path, doc) -> None:
    text = doc if isinstance(doc, str) else json.dumps(doc)
    (tmp_path / "medium.json").write_text(text)


def one_line_error(tmp_path) -> str:
    with pytest.raises(ResultError) as e:
        mediumfile.read(tmp_path)
    text = str(e.value)
    assert "\n" not in text and str(tmp_path / "medium.json") in text
    return text


def test_a_good_file_reads_back(tmp_path):
    write(tmp_path, GOOD)
    ch = mediumfile.read(tmp_path)
    assert ch is not None and ch.duration_s == 12.5
    assert ch.relay_lag == RelayLag(frames=400, mean_ms=0.2, over_1ms=4, max_ms=3.0)
    assert (ch.relay_lag_mean_ms, ch.relay_lag_over_1ms, ch.lateness_max_ms) == (0.2, 0.01, 0.5)
    assert ch.robots[0].frames_delivered == 9


def test_no_file_or_no_relay_lag_is_none(tmp_path):
    assert mediumfile.read(tmp_path) is None
    write(tmp_path, {k: v for k, v in GOOD.items() if k != "relay_lag"})
    ch = mediumfile.read(tmp_path)
    assert ch is not None and ch.relay_lag is None and ch.relay_lag_over_1ms is None


@pytest.mark.parametrize(
    ("relay_lag", "words"),
    [
        ("late", "'relay_lag' is str, not an object"),
        ({"frames": 4, "mean_ms": "late"}, "'mean_ms' is str"),
        ({"frames": 4.5, "mean_ms": 0.1}, "'frames' is float"),
        ({"frames": True, "mean_ms": 0.1}, "'frames' is bool"),
        ({"frames": 4, "mean_ms": -0.1}, "'mean_ms' is negative"),
        ({"frames": -4, "mean_ms": 0.1}, "'frames' is negative"),
        ({"frames": 4, "mean_ms": 0.1, "over_1ms": 5}, "more frames over 1 ms (5) than"),
    ],
)
def test_a_wrong_relay_lag_is_one_line(tmp_path, relay_lag, words):
    write(tmp_path, dict(GOOD, relay_lag=relay_lag))
    assert words in one_line_error(tmp_path)


def test_a_truncated_or_wrong_file_is_one_line(tmp_path):
    write(tmp_path, json.dumps(GOOD)[:40])
    assert "not valid JSON" in one_line_error(tmp_path)
    write(tmp_path, [1, 2])
    assert "not a JSON object" in one_line_error(tmp_path)
    write(tmp_path, {k: v for k, v in GOOD.items() if k != "now_s"})
    assert "no 'now_s'" in one_line_error(tmp_path)


def test_the_runs_verdict_reads_the_relay_lag_and_skips_a_bad_file(tmp_path, caplog):
    from testbed.run.results import channel_relay_lag

    assert channel_relay_lag(str(tmp_path)) is None  # a veth run
    write(tmp_path, GOOD)
    assert channel_relay_lag(str(tmp_path)) == RelayLag(400, 0.2, 4, 3.0)
    write(tmp_path, dict(GOOD, relay_lag={"frames": 4, "mean_ms": "late"}))
    with caplog.at_level(logging.WARNING):
        assert channel_relay_lag(str(tmp_path)) is None
    assert "relay lag not judged" in caplog.text and "'mean_ms' is str" in caplog.text
