"""The media section of the report: veth against ns3-wifi with 95% intervals, and per
measure where veth's answer is within the noise of 802.11's, on a synthetic media sweep with
known numbers; the airtime of a frame; protocols compared within each medium."""

import json

import pytest

from testbed.analysis import figures, media, protocols, report
from testbed.files import routingfile
from testbed.sweep import file as sweepfile
from tests.unit.test_analysis_runs import channel_doc
from tests.unit.test_sweep_synthetic import result_doc, write_run

# Per medium: steps (+5 per run index: within noise of each other), wall-clock median delay
# (+0.01 ms per index: far apart), control packets per robot per second.
STEPS = {"veth": 400, "ns3-wifi": 404}
DELAY_MS = {"veth": 0.05, "ns3-wifi": 0.5}
CONTROL = {"veth": 2.0, "ns3-wifi": 2.0}


def sweep(tmp_path, runs=3, routing=()):
    spec = sweepfile.SweepSpec.of(
        robots=(5,), comm_range=(20.0,), laser_range=(2.0,), runs=runs, time_scale=4.0,
        medium=("veth", "ns3-wifi"), routing=routing,
    )  # fmt: skip
    metrics = {}
    for run in sweepfile.expand(spec):
        c = run.config
        steps = STEPS[c.medium] + 5 * run.index + (50 if c.routing == "batman" else 0)
        d = write_run(tmp_path, run, result_doc(c, [steps] * 5, steps + 1))
        if c.medium == "ns3-wifi":
            (d / "medium.json").write_text(
                json.dumps(channel_doc(airtime=(1.0,) * 6, retries=(2,) * 6))
            )
        robot_s = 6 * 10.0 * c.time_scale  # 5 robots and the display, 10 s of wall time
        metrics[run.run_id] = {
            "duration_s": 10.0, "control_tx_packets": CONTROL[c.medium] * robot_s,
            "control_tx_bytes": 100.0 * CONTROL[c.medium] * robot_s,
            "tx_packets": 4 * CONTROL[c.medium] * robot_s,
            "tx_bytes": 1000.0 * 4 * CONTROL[c.medium] * robot_s,
            "pdf": 0.99 - 0.001 * run.index,
            "delay_ms_median": DELAY_MS[c.medium] + 0.01 * run.index,
        }  # fmt: skip
    return lambda run: routingfile.parse(m) if (m := metrics.get(run.run_id)) else None


def test_rows_per_medium_with_intervals_and_emulated_delay(tmp_path):
    made = figures.make_all(tmp_path, metrics_of=sweep(tmp_path))
    rows = {r.medium: r for r in made.tables.media}
    assert list(rows) == ["veth", "ns3-wifi"]
    v, w = rows["veth"], rows["ns3-wifi"]
    assert v.n == w.n == 3 and v.compared.steps.mean == 410 and w.compared.steps.mean == 414
    assert v.compared.steps.ci_low < 410 < v.compared.steps.ci_high
    assert w.compared.delay_ms.mean == pytest.approx((0.5 + 0.02) * 4.0)  # wall x time scale
    assert v.compared.control_pkts_per_robot_s.mean == pytest.approx(2.0)
    # A quarter of the frames are control frames of 100 bytes (40 us each at 54 Mbit/s), the
    # mean frame has 1000 bytes (172 us): 2.5% of the bytes, but 40 / (4 x 172) of the
    # airtime, as the preamble costs every frame the same.
    assert v.compared.control_airtime_share.mean == pytest.approx(40 / (4 * 172))
    assert w.channel.channel_airtime_share == pytest.approx(6.0 / 10.0)
    assert v.channel.channel_airtime_share is None  # veth has no channel counters
    # The paper's figures stay on one medium: veth's runs alone.
    assert [r.steps_per_run for r in made.tables.fig2] == [(405, 410, 415)]


def test_noise_sentences_say_where_veth_is_within_the_noise(tmp_path):
    made = figures.make_all(tmp_path, metrics_of=sweep(tmp_path))
    text = "\n".join(media.section(made.tables.media))
    assert "- Exploration steps: veth is within the noise of 802.11 at 1 of 1 points (all)." in text
    assert (
        "- Median delay (emulated ms): veth is within the noise of 802.11 at 0 of 1 points; "
        "beyond it at aodv, 20 m, 5 robots: veth 0.28 below 802.11's 2.08." in text
    )
    assert "| aodv | 20 | 5 | ns3-wifi | 3 | 414 [" in text
    assert "drawn from the veth runs alone" in text
    assert "| aodv | 20 | 5 | 0.600 | 0.020 | 18.0 | 0.20 | 1.0% |" in text  # the channel


def test_one_run_per_medium_is_not_judged(tmp_path):
    made = figures.make_all(tmp_path, metrics_of=sweep(tmp_path, runs=1))
    text = "\n".join(media.section(made.tables.media))
    assert "- Exploration steps: not judged: 1 point(s) with one run on a medium" in text
    assert "| aodv | 20 | 5 | veth | 1 | 405 |" in text


def test_report_has_the_section_only_when_media_vary(tmp_path):
    path, _ = report.write_report(tmp_path, metrics_of=sweep(tmp_path))
    assert "## What perfect links get wrong" in path.read_text()
    single = tmp_path / "single"
    spec = sweepfile.SweepSpec.of(robots=(2,), comm_range=(5.0,), laser_range=(2.0,),
                               medium="ns3-wifi")  # fmt: skip
    for run in sweepfile.expand(spec):
        write_run(single, run)
    path, _ = report.write_report(single, metrics_of=lambda run: None)
    assert "What perfect links" not in path.read_text()
    assert figures.make_all(single, metrics_of=lambda run: None).tables.media == []


def test_protocols_are_compared_within_each_medium(tmp_path):
    made = figures.make_all(tmp_path, metrics_of=sweep(tmp_path, routing=("aodv", "batman")))
    rows = made.tables.protocols
    assert [(r.medium, r.routing, r.measures.steps) for r in rows] == [
        ("ns3-wifi", "aodv", 414), ("ns3-wifi", "batman", 464),
        ("veth", "aodv", 410), ("veth", "batman", 460),
    ]  # fmt: skip
    text = "\n".join(protocols.section(rows))
    assert "| empty (ns3-wifi) | 20 | 5 | aodv |" in text and "| empty | 20 | 5 | aodv |" in text
    pairs = {(r.routing, r.medium) for r in made.tables.media}
    assert pairs == {(p, m) for p in ("aodv", "batman") for m in ("veth", "ns3-wifi")}


@pytest.mark.parametrize(
    ("standard", "rate", "phy"),
    [
        (None, None, ("ofdm", 54.0)),  # veth: priced at 802.11a's fastest
        ("80211a", "", ("ofdm", 54.0)),
        ("80211a", "minstrel", ("ofdm", 54.0)),
        ("80211a", "OfdmRate12Mbps", ("ofdm", 12.0)),
        ("80211b", "", ("dsss", 11.0)),
        ("80211b", "DsssRate1Mbps", ("dsss", 1.0)),
        ("80211b", "DsssRate5_5Mbps", ("dsss", 5.5)),
        ("80211g", "ErpOfdmRate6Mbps", ("erp", 6.0)),
    ],
)
def test_the_phy_of_a_run(standard, rate, phy):
    assert media.phy_of(standard, rate) == phy


def test_the_airtime_of_a_frame():
    # 100 bytes of Ethernet frame: 122 bytes of 802.11 frame, 976 bits.
    # 802.11a at 54: 16 + 976 + 6 = 998 bits in symbols of 216 -> 5 symbols of 4 us.
    assert media.frame_airtime_s(100, "ofdm", 54.0) == pytest.approx(40e-6)
    assert media.frame_airtime_s(100, "erp", 54.0) == pytest.approx(46e-6)
    # 802.11b at 1 Mbit/s: the long preamble, then one bit per microsecond.
    assert media.frame_airtime_s(100, "dsss", 1.0) == pytest.approx(192e-6 + 976e-6)
    assert media.traffic_airtime_s(2, 200, "dsss", 1.0) == pytest.approx(2 * (192e-6 + 976e-6))
    assert media.traffic_airtime_s(0, 0, "ofdm", 54.0) == 0.0


def test_the_channel_table_gives_the_raw_delay_of_runs_corrected_for_the_relay_lag(tmp_path):
    metrics_of = sweep(tmp_path)

    def corrected(run):
        m = metrics_of(run)
        if m is not None and run.config.medium == "ns3-wifi" and not run.run_id.endswith("k1"):
            raw = m.delay_ms_median + 0.25
            m = routingfile.parse({**m.to_json(), "delay_raw_ms_median": raw, "relay_lag": {}})
        return m

    made = figures.make_all(tmp_path, metrics_of=corrected)
    rows = {r.medium: r for r in made.tables.media}
    assert rows["ns3-wifi"].delay_lag_corrected_runs == 2
    text = "\n".join(media.section(made.tables.media))
    assert "corrected for the medium's relay lag" in text
    assert "| 1.0% | 3.10 | 2 of 3 |" in text  # runs 2 and 3: (0.5 + 0.02 + 0.25) x 4
