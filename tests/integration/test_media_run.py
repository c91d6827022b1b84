"""A whole exploration run on the ns3-wifi medium (docs/ns3-medium.md): real robots in real
namespaces, the real ns-3 process as their radio. Checked: the run works as on veth (the
results contract, maps flooded and received), config.json says which medium, medium.json
holds the channel's counters and the analysis reads them beside the captures' metrics
(frames the channel carried against frames the captures saw leave the robots), and nothing
of the testbed is left after the run."""

import json
import os

import pytest

from testbed.analysis import figures, media
from testbed.analysis.runs import load_run
from testbed.run.execute import RunConfig, run
from topology import state
from topology.kernel import netns
from topology.radio.ns3wifi import unbuilt_reason

# Skipped only where `make setup` said it could not build the medium (no ns-3, or g++ failed
# against this release's ns-3), with its line; where it was to be built, a missing build fails.
pytestmark = pytest.mark.skipif(unbuilt_reason() is not None, reason=str(unbuilt_reason()))

STEPS = 150  # 15 s of robot time: maps are flooded every 10 steps, goals sent at the start


def test_a_short_exploration_runs_on_ns3_wifi_and_keeps_the_channel_counters(tb_name, tmp_path):
    out = str(tmp_path / "run")
    # Time scale 3: what a loaded 2-core machine sustains with the channel (media.toml).
    cfg = RunConfig(robots=3, comm_range=20.0, laser_range=2.0, seed=5, time_scale=3.0,
                    max_steps=STEPS, capture=True, medium="ns3-wifi")  # fmt: skip
    result = run(cfg, out, tb_name, progress=False).to_json()
    assert result["status"] in ("complete", "step_cap"), result["status_detail"]
    assert result["steps"] <= STEPS
    assert result["config"]["extra"]["medium"] == "ns3-wifi"
    for r in result["robots"].values():  # every robot heard its teammates' maps over the air
        assert r["messages"]["sent"].get("map", 0) > 0
        assert r["messages"]["received"].get("map", 0) > 0

    with open(os.path.join(out, "medium.json")) as f:
        counters = json.load(f)
    assert len(counters["robots"]) == cfg.robots + 1  # and the display robot
    assert all(r["foreign"] == 0 for r in counters["robots"])

    rec = load_run(out)
    assert rec.config.medium == "ns3-wifi" and rec.network == ("aodv", "empty", "ns3-wifi")
    ch = rec.channel
    assert ch.duration_s > 0 and 0 < ch.airtime_share < 1
    assert all(r.frames_sent > 0 and r.frames_delivered > 0 for r in ch.robots)
    # Every frame a robot sent reached the channel: what its capture saw it send (its own
    # frames and those it forwards) is what the channel counted from it, give or take the
    # frames in flight when the captures stopped and those the kernel dropped from them.
    metrics = figures.capture_metrics(rec)
    assert metrics is not None
    sent, seen = ch.total("frames_sent"), metrics.tx_packets
    lost = metrics.capture_dropped_packets or 0
    assert abs(seen - sent) <= max(5, 0.02 * sent) + lost, (seen, sent, lost)
    row = media.run_row(rec, metrics)
    assert row.medium == "ns3-wifi" and 0 < row.control_airtime_share < 1
    assert row.channel_airtime_share == ch.airtime_share

    # Nothing of the testbed is left: no state, no namespace, no ns-3 process.
    assert not os.path.exists(state.state_path(tb_name))
    assert not [ns for ns in netns.list_names() if tb_name in ns]
    assert not medium_processes(tb_name)


def medium_processes(name: str) -> list[int]:
    """Pids of tb-ns3-wifi processes whose command line names the testbed."""
    pids = []
    for d in os.listdir("/proc"):
        try:
            with open(f"/proc/{d}/cmdline", "rb") as f:
                argv = f.read().split(b"\0")
        except OSError:
            continue
        if argv[0].endswith(b"tb-ns3-wifi") and any(name.encode() in a for a in argv):
            pids.append(int(d))
    return pids
