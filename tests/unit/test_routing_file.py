"""routing.json's type (testbed.files.routingfile): what pcapmetrics writes reads back into the
fields the report uses; a file that is not one (truncated, wrong types, shares or counts out of
range, a nested record that is not an object) is one line of ResultError naming the file and
the key; a cache that is not one is computed again from the captures, with a warning."""

import json
import logging

import pytest

from testbed.analysis import pcapmetrics
from testbed.files import routingfile
from testbed.files.routingfile import ResultError
from tests.unit import hostile_dirs as hd

GOOD = {
    "format": 8, "control_port": 654, "duration_s": 10.0, "overhead_packets": 0.25,
    "overhead_bytes": 0.1, "pdf": 0.95, "segment_delivery": 1.0, "delay_ms_mean": 0.4,
    "delay_ms_median": 0.2, "delay_ms_p95": 1.5, "delay_raw_ms_mean": 0.6,
    "delay_raw_ms_median": 0.3, "delay_raw_ms_p95": 2.0, "throughput_bps": 8000.0,
    "tx_packets": 400, "tx_bytes": 40000, "control_tx_packets": 100, "control_tx_bytes": 4000,
    "tcp_flows": 2, "tcp_transmissions": 130, "tcp_segments_sent": 100,
    "tcp_segments_delivered": 100,
    "relay_lag": {"records": 90, "segments_corrected": 95, "segments_uncorrected": 5,
                  "subtracted_ms_mean": 0.3},
    "middleware": {"name": "nanomsg", "tx_bytes": 9000, "protocol_bytes": 900},
    "daemon_comparison": {"pcap_control_tx_packets": 100, "daemon_tx_packets": 98,
                          "relative_difference": 0.02},
    "capture_dropped": {"packets": 0, "per_robot": {"r1": 0}},
    "captures_left_out": {"r3.pcap": "empty"},
    "emulated": {"time_scale": 2.0, "delay_ms_median": 0.4, "throughput_bps": 4000.0},
    "robots": {"r1": {"control_tx_packets": 100}},
    "pcaps": {"r1.pcap": "0" * 64},
}  # fmt: skip


def write(tmp_path, doc):
    path = tmp_path / "routing.json"
    path.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    return path


def test_a_good_file_reads_back(tmp_path):
    m = routingfile.read(write(tmp_path, GOOD))
    assert (m.format, m.pdf, m.delay_ms_median, m.control_tx_packets) == (8, 0.95, 0.2, 100)
    assert m.delay("delay_raw_ms_p95") == 2.0 and m.count("tcp_flows") == 2
    assert m.relay_lag is not None and m.relay_lag.segments_uncorrected == 5
    assert m.middleware is not None and m.middleware.protocol_bytes == 900
    assert m.daemon_comparison is not None and m.daemon_comparison.daemon_tx_packets == 98
    assert m.emulated is not None and m.emulated.get("delay_ms_median") == 0.4
    assert (m.capture_dropped_packets, dict(m.captures_left_out)) == (0, {"r3.pcap": "empty"})
    assert m.to_json() == GOOD  # the whole record, for writing out again


def test_absent_keys_are_none(tmp_path):
    m = routingfile.read(write(tmp_path, {"format": 8}))
    assert (m.pdf, m.relay_lag, m.emulated, m.daemon_comparison) == (None, None, None, None)


@pytest.mark.parametrize(
    ("change", "words"),
    [
        ({"pdf": "0.9"}, "'pdf' is str"),
        ({"pdf": 7.5}, "'pdf' is 7.5, not a share"),
        ({"overhead_packets": -0.1}, "'overhead_packets' is -0.1, not a share"),
        ({"tx_packets": -3}, "'tx_packets' is negative"),
        ({"tcp_flows": True}, "'tcp_flows' is bool"),
        ({"format": 8.0}, "'format' is float"),
        ({"relay_lag": [1]}, "'relay_lag' is list, not an object"),
        ({"middleware": {"tx_bytes": "lots"}}, "'middleware': 'tx_bytes' is str"),
        ({"emulated": {"time_scale": 0}}, "'emulated': 'time_scale'"),
        ({"emulated": {"delay_ms_median": 0.4}}, "'emulated': no 'time_scale'"),
        ({"capture_dropped": {"packets": -1}}, "'capture_dropped': 'packets' is negative"),
    ],
)
def test_a_wrong_value_is_one_line_naming_file_and_key(tmp_path, change, words):
    path = write(tmp_path, {**GOOD, **change})
    with pytest.raises(ResultError) as e:
        routingfile.read(path)
    text = str(e.value)
    assert "\n" not in text and text.startswith(f"{path}: ") and words in text


@pytest.mark.parametrize(("text", "words"), [(json.dumps(GOOD)[:60], "not valid JSON"),
                                              ("[]", "not a JSON object")])  # fmt: skip
def test_a_truncated_or_wrong_file_is_one_line(tmp_path, text, words):
    with pytest.raises(ResultError, match=words):
        routingfile.read(write(tmp_path, text))
    with pytest.raises(ResultError, match="no such file"):
        routingfile.read(tmp_path / "none.json")


def test_what_pcapmetrics_writes_reads_back_and_a_bad_cache_is_computed_again(tmp_path, caplog):
    run = hd.run_dir(tmp_path / "s")
    (run / "pcaps").mkdir()
    for k in (1, 2):
        (run / "pcaps" / f"r{k}.pcap").write_bytes(hd.udp_pcap(k, 3))
    first = pcapmetrics.run_metrics(run)
    assert first is not None
    cached = routingfile.read(run / "routing.json")
    assert cached.format == pcapmetrics.CACHE_FORMAT and cached.tx_packets == first.tx_packets
    assert pcapmetrics.run_metrics(run) == first  # from the cache
    doc = json.loads((run / "routing.json").read_text())
    (run / "routing.json").write_text(json.dumps(dict(doc, tx_packets="six")))
    with caplog.at_level(logging.WARNING):
        again = pcapmetrics.run_metrics(run)
    assert again == first and "'tx_packets' is str" in caplog.text
    assert "computed again" in caplog.text


def test_testbed_metrics_writes_a_metrics_json_of_the_same_type(tmp_path, capsys):
    cap = tmp_path / "cap"
    (cap / "daemons").mkdir(parents=True)
    for k in (1, 2):
        (cap / f"r{k}.pcap").write_bytes(hd.udp_pcap(k, 3))
    (cap / "daemons" / "network.json").write_text(json.dumps({"routing": "aodv",
                                                               "time_scale": 4.0}))  # fmt: skip
    status, out, _ = hd.testbed(["metrics", str(cap)], capsys)
    assert status == 0 and "written to" in out
    m = routingfile.read(cap / "metrics.json")
    assert m.pcaps is None and m.emulated is not None and m.emulated.time_scale == 4.0
    assert m.tx_packets == 6 and m.control_tx_packets == 0
