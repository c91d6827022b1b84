"""`testbed report RUN_DIR`: one run's routing.json and summary, with delays in emulated
time and the explanations a first reader needs."""

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import pytest

from testbed.analysis import pcapmetrics, routingnotes, runreport
from testbed.analysis.runs import load_run
from testbed.files import routingfile
from testbed.sweep import file as sweepfile
from tests.unit import test_pcapmetrics as tp
from tests.unit.hostile_dirs import EMPTY_PCAP
from tests.unit.test_sweep_synthetic import result_doc, write_run

REPO = Path(__file__).resolve().parents[2]


def one_run(tmp_path, time_scale=10.0):
    spec = sweepfile.SweepSpec.of(robots=(2,), comm_range=(5.0,), laser_range=(2.0,), runs=1)
    run = sweepfile.expand(spec)[0]
    config = dataclasses.replace(run.config, time_scale=time_scale)
    doc = result_doc(config, [817, 823], 823)
    doc["time_scale_achieved"] = time_scale
    return write_run(tmp_path, run, doc)


def report(*args):
    return subprocess.run([sys.executable, "-m", "testbed.analysis.report", *map(str, args)],
                          capture_output=True, text=True, cwd=REPO)  # fmt: skip


def test_emulated_delays_are_wall_times_the_time_scale():
    m = {"delay_ms_mean": 11.2, "delay_ms_median": 0.010, "delay_ms_p95": 40.0,
         "duration_s": 60.0, "throughput_bps": 8000.0}  # fmt: skip
    e = routingnotes.emulated(m, 12.0)
    assert e["time_scale"] == 12.0
    assert e["delay_ms_mean"] == pytest.approx(134.4)
    assert e["delay_ms_median"] == pytest.approx(0.12)
    assert e["duration_s"] == pytest.approx(720.0)
    assert e["throughput_bps"] == pytest.approx(8000.0 / 12)
    assert routingnotes.emulated(m, None) is None


def test_routing_json_says_what_its_numbers_mean_and_gives_emulated_time(tmp_path, monkeypatch):
    d = one_run(tmp_path / "s", time_scale=12.0)
    (d / "pcaps").mkdir()
    for k in (1, 2, 3):
        (d / "pcaps" / f"r{k}.pcap").write_bytes(EMPTY_PCAP)  # a header (an empty file is left out)
    monkeypatch.setattr(pcapmetrics, "read_pcaps", lambda paths: tp.chain_captures())
    monkeypatch.setattr(pcapmetrics, "robot_addr", lambda k: tp.ADDRS[k])
    m = pcapmetrics.run_metrics(d)
    doc = json.loads((d / "routing.json").read_text())
    assert doc["format"] == pcapmetrics.CACHE_FORMAT == 8
    assert set(doc["about"]) == {"pdf", "segment_delivery", "delay", "time"}
    assert "0.957 against 1.0" in doc["about"]["segment_delivery"]
    assert "mean far above the median" in doc["about"]["delay"]
    assert doc["emulated"]["time_scale"] == 12.0
    assert doc["emulated"]["delay_ms_median"] == pytest.approx(12.0 * m.delay_ms_median)
    text = runreport.summary(load_run(d), m)
    assert "| delay, median (ms) |" in text and "emulated (x 12)" in text
    assert f"PDF {m.pdf:.3f} against segment delivery {m.segment_delivery:.3f}" in text
    assert "Mean delay" in text and "against median" in text


def test_report_of_a_run_directory_writes_its_summary(tmp_path):
    d = one_run(tmp_path)
    r = report(d)
    assert r.returncode == 0, r.stderr
    text = (d / "summary.md").read_text()
    assert text == r.stdout
    assert "Status **complete**" in text
    # the two quantities called "steps", each under its own name
    assert "when the last robot finished): 823" in text
    assert "mean of the robots' finishing steps, as Fig. 2 plots): 820.0" in text
    assert "No packet captures in this run" in text
    assert not (d / "routing.json").exists()  # nothing to compute it from


def test_report_of_a_malformed_run_or_neither_is_one_line_and_exit_2(tmp_path):
    d = tmp_path / "run"
    d.mkdir()
    (d / "result.json").write_text('{"status": "complete"}')
    r = report(d)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert "result.json: no 'config'" in r.stderr and "Traceback" not in r.stderr
    r = report(tmp_path / "empty")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert "neither a sweep directory" in r.stderr


def test_a_run_on_ns3_wifi_shows_the_channel_counters(tmp_path):
    from tests.unit.test_analysis_runs import channel_doc

    spec = sweepfile.SweepSpec.of(robots=(1,), comm_range=(5.0,), laser_range=(2.0,),
                               medium="ns3-wifi", wifi_standard="80211b",
                               wifi_rate="DsssRate1Mbps")  # fmt: skip
    run = sweepfile.expand(spec)[0]
    d = write_run(tmp_path, run, result_doc(run.config, [300], 301))
    (d / "medium.json").write_text(json.dumps(channel_doc()))
    text = runreport.summary(load_run(d), None)
    assert "seed " in text and ", medium ns3-wifi." in text
    assert "## The 802.11 channel (ns3-wifi, from medium.json)" in text
    assert "80211b at DsssRate1Mbps; 10.0 s of emulated time. Air in use" in text
    assert (
        "7.50%" in text and "frames the MACs lost (retry limit, full or expired queue): 6" in text
    )
    assert "| r1 | 100 | 180 | 3 | 3 | 500.0 |" in text
    assert "| r2 (display) | 100 | 180 | 1 | 3 | 250.0 |" in text
    # a veth run has no such section
    assert "802.11 channel" not in runreport.summary(load_run(one_run(tmp_path / "v")), None)


def test_a_run_whose_delays_were_corrected_for_the_relay_lag_says_so(tmp_path):
    from tests.unit.test_analysis_runs import channel_doc

    spec = sweepfile.SweepSpec.of(robots=(1,), comm_range=(5.0,), laser_range=(2.0,),
                               medium="ns3-wifi")  # fmt: skip
    run = sweepfile.expand(spec)[0]
    d = write_run(tmp_path, run, result_doc(run.config, [300], 301))
    (d / "medium.json").write_text(json.dumps(channel_doc()))
    m = {"delay_ms_mean": 0.3, "delay_ms_median": 0.2, "delay_ms_p95": 0.9,
         "delay_raw_ms_mean": 0.6, "delay_raw_ms_median": 0.5, "delay_raw_ms_p95": 1.4,
         "relay_lag": {"records": 900, "segments_corrected": 95, "segments_uncorrected": 5,
                       "subtracted_ms_mean": 0.3, "subtracted_ms_median": 0.3}}  # fmt: skip
    m["emulated"] = routingnotes.emulated(m, 2.0)
    text = runreport.summary(load_run(d), routingfile.parse(m))
    assert "| delay, median, corrected for the relay lag (ms) | 0.200 | 0.400 |" in text
    assert "| delay, median, raw (ms) | 0.500 | 1.000 |" in text
    assert "95 segments had the lag of their hop frames taken out (0.300 ms" in text
    assert "5 could not be matched" in text
    assert "The routing delays above have each frame's relay lag taken out." in text
    # an ns3-wifi run that did not record the lag: its delays say they include it
    old = {k: v for k, v in m.items() if not k.startswith("delay_raw") and k != "relay_lag"}
    text = runreport.summary(load_run(d), routingfile.parse(old))
    assert "| delay, median (ms) | 0.200 |" in text and "raw" not in text
    assert "The routing delays include the relay lag" in text
