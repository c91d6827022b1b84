"""The ns3-wifi medium in real namespaces with the real ns-3 process (docs/ns3-medium.md):
routing over it, cut-offs, broadcast range, shared airtime, time scale, clean-up, and each
frame's relay lag taken out of the delays."""

import json
import os
import signal
import statistics
import subprocess
import sys
import time
import uuid

import pytest

from common.errors import TestbedError
from testbed.analysis import pcapmetrics, relaylag
from topology import names, state
from topology.kernel import netns
from topology.network import Network, destroy
from topology.radio.ns3wifi import unbuilt_reason
from topology.spec import NetworkSpec

from .test_medium import _neighbour_routes, _received, _start_listeners

# Skipped only where `make setup` said it could not build the medium (no ns-3, or g++ failed
# against this release's ns-3), with its line; where it was to be built, a missing build fails.
pytestmark = pytest.mark.skipif(unbuilt_reason() is not None, reason=str(unbuilt_reason()))

PORT = 47000
PROBE = [sys.executable, "-m", "tests.integration.probe"]
REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def wifi(name, positions, comm_range=10.0, **kw) -> Network:
    return Network(
        NetworkSpec(
            name=name, positions=tuple(positions), comm_range=comm_range, medium="ns3-wifi", **kw
        )
    )


def wait_for(condition, timeout: float, what: str):
    """Poll `condition` until it returns something true; fail after `timeout` seconds."""
    deadline = time.monotonic() + timeout
    while True:
        value = condition()
        if value:
            return value
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.05)


def ns3_pid(net: Network) -> int:
    return next(p.pid for p in state.read(net.name).processes if p.role == "ns3-wifi")


def ping(net: Network, k: int, dst: str, *args: str) -> subprocess.CompletedProcess:
    return net.exec(k, ["ping", "-n", *args, dst], capture_output=True, text=True, timeout=60)


def totals(counters: dict, key: str) -> float:
    return sum(r[key] for r in counters["robots"])


def test_chain_routes_over_two_hops_with_aodv(tb_name, aodv_daemon):
    """AODV over ns-3's 802.11 channel, with each AODV daemon (the `aodv_daemon` fixture)."""
    positions = [(0, 0), (8, 0), (16, 0)]
    with wifi(tb_name, positions, routing="aodv", aodv_daemon=aodv_daemon) as net:
        assert net.medium.kernel_links() == {(1, 2), (2, 3)}
        # The first request may be lost to discovery: retry until a reply comes back.
        wait_for(lambda: ping(net, 1, "10.0.0.3", "-c", "1", "-W", "2").returncode == 0,
                 30, "a reply from r3")  # fmt: skip
        out = ping(net, 1, "10.0.0.3", "-c", "5", "-i", "0.2", "-W", "2")
        assert " 0% packet loss" in out.stdout, out.stdout
        assert "ttl=63" in out.stdout  # the reply crossed one router: two hops
        route = net.exec(1, ["ip", "route", "get", "10.0.0.3"], capture_output=True, text=True)
        assert "via 10.0.0.2" in route.stdout, route.stdout
        c = net.medium.counters()
        assert totals(c, "to_linux") > 0 and totals(c, "from_linux") > 0
        # Acknowledgements work: without the frame exchange manager's address every unicast
        # would be retried 7 times (retries >> frames sent).
        assert totals(c, "retries") < totals(c, "mac_tx"), c
        assert all(r["airtime_s"] > 0 for r in c["robots"])
        assert c["relay_lag"]["frames"] == totals(c, "from_linux") + totals(c, "to_linux")


@pytest.mark.parametrize("routing", ["oracle", "babel", "batman"])
def test_the_other_routings_and_captures_work_as_on_veth(tb_name, tmp_path, routing):
    cap = str(tmp_path / "pcaps")
    with wifi(tb_name, [(0, 0), (8, 0), (16, 0)], routing=routing, capture_dir=cap) as net:
        wait_for(lambda: ping(net, 1, "10.0.0.3", "-c", "1", "-W", "1").returncode == 0,
                 60, f"r3 to answer over {routing}")  # fmt: skip
        out = ping(net, 1, "10.0.0.3", "-c", "3", "-i", "0.2", "-W", "2")
        assert "ttl=63" in out.stdout, out.stdout  # two hops
    pcap = subprocess.run(["tcpdump", "-nr", f"{cap}/r2.pcap", "icmp"], capture_output=True,
                          text=True)  # fmt: skip
    assert "10.0.0.1 > 10.0.0.3: ICMP echo request" in pcap.stdout  # r2 forwarded them


def test_a_robot_that_leaves_is_cut_off_within_a_step(tb_name):
    with wifi(tb_name, [(0, 0), (5, 0)]) as net:
        _neighbour_routes(net)
        wait_for(lambda: ping(net, 1, "10.0.0.2", "-c", "1", "-W", "2").returncode == 0,
                 20, "r2 to answer")  # fmt: skip
        net.move(2, (50, 0))  # returns once the simulator has the new position
        assert net.medium.kernel_links() == set()
        out = ping(net, 1, "10.0.0.2", "-c", "5", "-i", "0.2", "-W", "1")
        assert " 0 received" in out.stdout, out.stdout
        net.move(2, (9, 0))
        assert net.medium.kernel_links() == {(1, 2)}
        wait_for(lambda: ping(net, 1, "10.0.0.2", "-c", "1", "-W", "2").returncode == 0,
                 20, "r2 to answer again")  # fmt: skip


def test_a_broadcast_reaches_only_the_robots_in_range(tb_name, tmp_path):
    # r1 - r2 - r3 in a row, 8 m apart, range 10: r2 hears both, r1 and r3 only r2.
    with wifi(tb_name, [(0, 0), (8, 0), (16, 0)]) as net:
        outs = _start_listeners(net, tmp_path)
        for k in (1, 2, 3):
            argv = PROBE + ["send", str(PORT), "255.255.255.255", "--count", "20",
                            "--gap", "0.02", "--tag", f"b{k}"]  # fmt: skip
            assert net.exec(k, argv, cwd=REPO, timeout=60).returncode == 0

        def heard() -> dict[int, set[str]]:
            got = {k: set() for k in (1, 2, 3)}
            for tag in ("b1", "b2", "b3"):
                for k, srcs in _received(outs, tag).items():
                    got[k] |= srcs - {names.robot_addr(k)}  # minus its own loopback
            return got

        want = {1: {"10.0.0.2"}, 2: {"10.0.0.1", "10.0.0.3"}, 3: {"10.0.0.2"}}
        wait_for(lambda: heard() == want, 10, f"broadcasts heard as {want}")
        time.sleep(0.3)  # anything late would show now
        assert heard() == want


def _iperf_servers(net: Network, robots_ports: list[tuple[int, int]]) -> None:
    for k, port in robots_ports:
        net.spawn(k, ["iperf3", "-s", "-1", "-p", str(port)], role="iperf3",
                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
    # iperf3 -s says nothing when it listens: wait until each port is bound.
    for k, port in robots_ports:
        wait_for(lambda k=k, port=port: f":{port} " in net.exec(
            k, ["ss", "-Htln"], capture_output=True, text=True).stdout,
            10, f"iperf3 to listen on r{k}:{port}")  # fmt: skip


def _iperf_clients(net: Network, flows: list[tuple[int, int, int]], seconds: int, tmp_path):
    """flows: (client robot, server robot, port). UDP offered well above what 802.11a
    carries, so the channel is the bottleneck. Returns each flow's received Mbit/s."""
    procs = []
    for src, dst, port in flows:
        out = tmp_path / f"iperf-{src}-{port}.json"
        argv = ["iperf3", "-c", names.robot_addr(dst), "-p", str(port), "-u", "-b", "60M",
                "-l", "1200", "-t", str(seconds), "-J"]  # fmt: skip
        with open(out, "w") as f:
            procs.append((net.spawn(src, argv, role="iperf3", stdout=f,
                                    stderr=subprocess.DEVNULL), out))  # fmt: skip
    rates = []
    for p, out in procs:
        p.wait(timeout=seconds + 60)
        report = json.loads(out.read_text())
        rates.append(report["end"]["sum_received"]["bits_per_second"] / 1e6)
    return rates


def test_two_flows_in_one_room_share_the_airtime(tb_name, tmp_path):
    # Four robots within a metre of each other: everyone hears everyone, one channel.
    with wifi(tb_name, [(0, 0), (1, 0), (0, 1), (1, 1)]) as net:
        _neighbour_routes(net)
        for k in (1, 3):  # ARP first, so no flow starts with a lost burst
            peer = names.robot_addr(k + 1)
            wait_for(lambda k=k, peer=peer: ping(net, k, peer, "-c", "1", "-W", "2").returncode
                     == 0, 20, f"r{k + 1} to answer")  # fmt: skip

        _iperf_servers(net, [(2, 5201)])
        (one,) = _iperf_clients(net, [(1, 2, 5201)], 4, tmp_path)
        _iperf_servers(net, [(2, 5202), (4, 5203)])
        first, second = _iperf_clients(net, [(1, 2, 5202), (3, 4, 5203)], 4, tmp_path)

        c = net.medium.counters()
        print(f"one flow alone {one:.1f} Mbit/s; two flows {first:.1f} + {second:.1f}; "
              f"lateness {c['lateness']}")  # fmt: skip
        # 802.11a at 54 Mbit/s carries ~30 Mbit/s of UDP; a veth carries gigabits.
        assert 5 < one < 45, one
        # The two flows share one channel: together about what one gets alone, and each
        # clearly less than it.
        assert 0.6 * one < first + second < 1.4 * one, (one, first, second)
        assert first < 0.8 * one and second < 0.8 * one, (one, first, second)
        assert totals(c, "queue_drops") > 0  # the offered load overflowed the MAC queues


def test_time_scale_runs_the_channel_faster(tb_name):
    with wifi(tb_name, [(0, 0), (5, 0)], time_scale=4.0) as net:
        t0, s0 = time.monotonic(), net.medium.counters()["now_s"]
        time.sleep(1.0)
        t1, s1 = time.monotonic(), net.medium.counters()["now_s"]
        assert 3.0 < (s1 - s0) / (t1 - t0) < 4.5, (s1 - s0, t1 - t0)


def test_nothing_left_behind_after_down_or_clean(tb_name):
    net = wifi(tb_name, [(0, 0), (5, 0)])
    net.up()
    pid = ns3_pid(net)
    sock = net.medium.sock_path
    assert os.path.exists(sock)
    net.down()
    assert not os.path.exists(f"/proc/{pid}") or _zombie(pid)
    assert not os.path.exists(sock)
    assert not any(names.parse_ns(ns) and names.parse_ns(ns)[0] == tb_name
                   for ns in netns.list_names())  # fmt: skip

    # A testbed left behind by a process that died (`net up`, then SIGKILL): clean-up by
    # the recorded pid, as `testbed clean` does.
    net = Network(wifi(tb_name, [(0, 0), (5, 0)]).spec, persistent=True)
    net.up()
    pid = ns3_pid(net)
    net.detach()
    os.kill(pid, 0)  # still running without its owner
    destroy(tb_name)
    assert not os.path.exists(f"/proc/{pid}") or _zombie(pid)
    assert state.read(tb_name) is None


def _zombie(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] == "Z"
    except FileNotFoundError:
        return True


def test_the_process_dies_cleanly_on_sigterm(tb_name):
    """The medium needs no shutdown request: SIGTERM (what destroy sends) ends it at once."""
    with wifi(tb_name, [(0, 0), (5, 0)]) as net:
        pid = ns3_pid(net)
        proc = net.children[pid]
        os.kill(pid, signal.SIGTERM)
        assert proc.wait(timeout=5) == -signal.SIGTERM
        with pytest.raises(TestbedError, match="does not answer"):
            net.move(2, (6, 0))  # a dead medium is one clear error, not a traceback


def test_net_up_move_links_and_down_by_hand(tb_name):
    """The CLI: `net up --medium ns3-wifi`, then other processes attach to move and look."""
    cli = [sys.executable, "-m", "testbed.cli", "net"]

    def tb(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run(cli + list(args), capture_output=True, text=True, cwd=REPO,
                              timeout=120)  # fmt: skip

    up = tb("up", tb_name, "--robots", "3", "--spacing", "8", "--comm-range", "10",
            "--medium", "ns3-wifi")  # fmt: skip
    assert up.returncode == 0, up.stderr
    pid = next(p.pid for p in state.read(tb_name).processes if p.role == "ns3-wifi")
    assert tb("links", tb_name).stdout.split("\n")[:2] == ["1 2", "2 3"]
    assert tb("move", tb_name, "r3", "40", "0").returncode == 0
    assert tb("links", tb_name).stdout.strip() == "1 2"
    impair = tb("impair", tb_name, "r1", "r2", "--loss", "10")
    assert impair.returncode == 2 and "no link impairments" in impair.stderr
    assert tb("down", tb_name).returncode == 0
    assert not os.path.exists(f"/proc/{pid}") or _zombie(pid)


@pytest.fixture
def rlg_name() -> str:
    """A testbed name for the relay-lag test, cleaned up like tb_name's."""
    from .conftest import SESSION_TAG, _made

    name = f"rlg{SESSION_TAG}{uuid.uuid4().hex[:4]}"
    _made.append(name)
    yield name
    destroy(name)


def _first_receptions(frames, addrs) -> dict[tuple, object]:
    """TCP data segments r3 received, first copy of each (flow, seq)."""
    out = {}
    for f in sorted(frames, key=lambda f: f.time):
        if f.ip_dst == addrs[3] and f.ip_proto == 6 and f.tcp_len:
            out.setdefault((f.ip_src, f.tcp_sport, f.tcp_dport, f.tcp_seq), f)
    return out


def test_each_frames_relay_lag_is_recorded_and_taken_out_of_the_delays(rlg_name, tmp_path):
    """TCP over two hops (r1 -> r2 -> r3) at time scale 2: every frame delivered leaves one
    record; each segment's corrected delay is its raw delay less the lag of its two hop
    frames, which leaves at least the air's time and never less than nothing."""
    cap, scale = str(tmp_path / "pcaps"), 2.0
    spec = dict(routing="oracle", capture_dir=cap, time_scale=scale)
    with wifi(rlg_name, [(0, 0), (8, 0), (16, 0)], **spec) as net:
        wait_for(lambda: ping(net, 1, "10.0.0.3", "-c", "1", "-W", "1").returncode == 0,
                 30, "r3 to answer over two hops")  # fmt: skip
        _iperf_servers(net, [(3, 5301)])
        client = ["iperf3", "-c", "10.0.0.3", "-p", "5301", "-t", "2", "-b", "2M", "-l", "1000"]
        assert net.exec(1, client, capture_output=True, timeout=60).returncode == 0
        c = net.medium.counters()
        net.medium.keep_lag_file(str(tmp_path / names.LAG_FILE))
    records, partial = relaylag.read_records(tmp_path / names.LAG_FILE)
    assert partial == 0
    # One record per frame delivered to a robot (the counters are one snapshot; the copy,
    # a moment later, may hold a few more), each with its sender; none past the cap.
    assert c["lag_file"]["records"] == totals(c, "to_linux"), c["lag_file"]
    assert c["lag_file"]["records"] <= len(records) <= c["lag_file"]["records"] + 50
    assert c["lag_file"]["not_written"] == 0 and c["lag_file"]["untagged"] == 0
    assert all(r.sender in (1, 2, 3) and r.sender != r.receiver for r in records)
    # Plausible: under a second each (a quiet relay takes tens to hundreds of us).
    assert max(r.lag_ns for r in records) < 1e9
    assert statistics.median(r.lag_ns for r in records) > 0

    addrs = {k: names.robot_addr(k) for k in (1, 2, 3)}
    pcaps = {k: tmp_path / "pcaps" / f"r{k}.pcap" for k in (1, 2, 3)}
    captures = pcapmetrics.read_pcaps(pcaps)
    raw = pcapmetrics.compute(captures, addrs)
    fixed = pcapmetrics.compute(captures, addrs, lags=records)
    assert fixed["delay_raw_ms_median"] == raw["delay_ms_median"]  # the old numbers, kept
    rl = fixed["relay_lag"]
    delivered = fixed["tcp_segments_delivered"]
    assert delivered > 100 and rl["segments_corrected"] >= 0.95 * delivered, rl
    assert fixed["delay_ms_median"] < raw["delay_ms_median"]

    # Segment by segment: corrected = raw - the lag of its two hops (r1 -> r2, r2 -> r3).
    index = relaylag.LagIndex(records)
    sent = {}
    for f in sorted(captures[1], key=lambda f: f.time):
        if f.ip_src == addrs[1] and f.ip_proto == 6 and f.tcp_len:
            sent.setdefault((f.ip_src, f.tcp_sport, f.tcp_dport, f.tcp_seq), f)
    corrected = []
    for key, got in _first_receptions(captures[3], addrs).items():
        if key not in sent:
            continue
        pk = relaylag.packet_key(addrs[1], addrs[3], got.ip_id, 6, got.tcp_seq)
        path = index.path_lag(pk, 1, 3, sent[key].time, got.time)
        if path is None:
            continue
        assert [(r.sender, r.receiver) for r in path] == [(1, 2), (2, 3)]
        corrected.append(1000 * (got.time - sent[key].time) - sum(r.lag_ns for r in path) / 1e6)
    # (pcapmetrics also corrects the few segments of iperf3's control data, from r3 to r1)
    assert 0.95 * rl["segments_corrected"] <= len(corrected) <= rl["segments_corrected"]
    assert statistics.median(corrected) == pytest.approx(fixed["delay_ms_median"], abs=0.02)
    # What is left is the channel's: at least two frames' preambles (20 us each at 802.11a)
    # in wall time, and no segment over-corrected below nothing.
    assert min(corrected) > 2 * 0.020 / scale, sorted(corrected)[:5]
    print(f"relay lag: {len(records)} records, median delay raw {raw['delay_ms_median']:.3f} "
          f"ms, corrected {fixed['delay_ms_median']:.3f} ms (wall); {rl}")  # fmt: skip
