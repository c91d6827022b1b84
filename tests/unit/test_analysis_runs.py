"""The analysis's one reader of result.json: typed values, defaults for old results, and
one clear line for a malformed file."""

import dataclasses
import json

import pytest

from testbed.analysis.runs import ResultError, load_run, load_runs
from testbed.sweep import file as sweepfile
from tests.unit.test_sweep_synthetic import result_doc, timer_plans, write_run


def one_run(tmp_path, **config):
    spec = sweepfile.SweepSpec.of(robots=(2,), comm_range=(5.0,), laser_range=(2.0,), runs=1)
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
    assert run.network == ("aodv", "empty", "veth")
    assert run.unimpaired


def test_whether_tcp_kept_emulated_time_is_read_from_the_networks_verdict(tmp_path):
    cases = [
        (1.0, None, True),  # the wall clock is emulated time
        (6.0, {"ok": True}, True),  # the network's timers dilated
        (6.0, {"ok": False, "reason": "no tcp_rto_min_us"}, False),
        (6.0, None, False),  # a dilated run made before the timers were dilated
    ]
    for i, (scale, network, want) in enumerate(cases):
        d = one_run(tmp_path / str(i), time_scale=scale)
        doc = json.loads((d / "result.json").read_text())
        doc["fidelity"] = {"ok": True}
        if network is not None:
            doc["fidelity"]["network"] = network
        (d / "result.json").write_text(json.dumps(doc))
        run = load_run(d)
        assert run.tcp_in_emulated_time is want, (scale, network)
        assert run.usable  # the exploration's verdict is apart from the network's
    assert run.network_faithful is None
    assert load_run(tmp_path / "2" / "runs" / d.name).network_reason == "no tcp_rto_min_us"


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


def channel_doc(airtime=(0.5, 0.25), retries=(3, 1)) -> dict:
    """A medium.json as tb-ns3-wifi writes it (docs/ns3-medium.md, "Counters")."""
    robot = {"from_linux": 100, "to_linux": 180, "foreign": 0, "mac_tx": 100, "retry_drops": 1,
             "mac_tx_drops": 0, "queue_drops": 2, "queued": 0, "queue_expired": 0,
             "phy_tx_drops": 0, "phy_rx_drops": 4, "phy_rx_drop_reasons": {"TXING": 4}}  # fmt: skip
    return {
        "now_s": 10.0,
        "qos": False,
        "lateness": {"probes": 1000, "max_ms": 2.5, "mean_ms": 0.1, "over_1ms": 3},
        "relay_lag": {"frames": 400, "max_ms": 3.0, "mean_ms": 0.2, "over_1ms": 4},
        "robots": [
            dict(robot, airtime_s=a, retries=r) for a, r in zip(airtime, retries, strict=True)
        ],
    }


def test_the_channel_counters_are_read_beside_the_result(tmp_path):
    d = one_run(tmp_path, medium="ns3-wifi", wifi_standard="80211b", wifi_rate="DsssRate1Mbps")
    (d / "medium.json").write_text(json.dumps(channel_doc()))
    run = load_run(d)
    assert (run.config.medium, run.config.wifi_standard) == ("ns3-wifi", "80211b")
    assert run.network == ("aodv", "empty", "ns3-wifi")
    c = run.channel
    assert [r.name for r in c.robots] == ["r1", "r2"]
    assert (c.robots[0].retries, c.robots[1].airtime_s, c.robots[0].frames_delivered) == (
        3, 0.25, 180)  # fmt: skip
    assert c.airtime_share == 0.75 / 10.0
    assert c.retry_rate == 4 / 200
    assert c.drops == 2 * (1 + 2)
    assert (c.relay_lag_mean_ms, c.relay_lag_over_1ms, c.lateness_max_ms) == (0.2, 0.01, 2.5)


def test_medium_read_from_config_extra_as_run_writes_it(tmp_path):
    d = one_run(tmp_path)
    doc = json.loads((d / "result.json").read_text())
    doc["config"]["extra"] = {"medium": "ns3-wifi", "wifi_standard": "80211a", "wifi_rate": ""}
    (d / "result.json").write_text(json.dumps(doc))
    run = load_run(d)
    assert (run.config.medium, run.config.wifi_standard, run.config.wifi_rate) == (
        "ns3-wifi", "80211a", "")  # fmt: skip
    assert run.channel is None  # no medium.json: no counters, and no error


@pytest.mark.parametrize(
    "text, says",
    [
        ("{oops", "medium.json: unreadable"),
        ('{"now_s": 1.0, "robots": {}}', "'robots' is not a list"),
        ('{"robots": []}', "no 'now_s'"),
        ('{"now_s": 1, "robots": [{"retries": "many"}]}', "robot 1: 'retries' is str"),
    ],
)
def test_a_malformed_medium_json_is_one_line_naming_it(tmp_path, text, says):
    d = one_run(tmp_path)
    (d / "medium.json").write_text(text)
    with pytest.raises(ResultError) as e:
        load_run(d)
    assert says in str(e.value) and "medium.json" in str(e.value)
    assert load_runs(tmp_path) == []  # a sweep's report leaves it out, as a bad result.json
