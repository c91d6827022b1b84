"""The AODV daemon in real namespaces (topology.Network with routing="aodv").

Each test runs against both daemons, the Python reference and the compiled one (the
`aodv_daemon` fixture, tests/integration/conftest.py), and builds its own testbed named "ta"
+ random hex ("tcw" for the last two, which ask for the daemon through `testbed net up` and
`testbed run`), which it removes in a finally. A test that starts a daemon itself takes its
command line from `daemon_argv`, the one place that knows both programs' names.
Time scales above 1 shorten the waits: a time scale K runs every protocol timer K times
faster (HELLO, lifetimes, ring search), so the same protocol events happen sooner.
"""

import contextlib
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
import uuid

from aodv import packet as wire
from aodv.kernel import UseMonitor
from aodv.stats import read_fresh
from aodv.statsfile import DaemonStats
from topology import routing, state
from topology.names import ROBOT_IFACE
from topology.network import Network, destroy
from topology.spec import NetworkSpec

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PY = os.path.join(REPO, ".venv", "bin", "python")
CHAIN5 = tuple((8.0 * i, 0.0) for i in range(5))


@contextlib.contextmanager
def aodv_net(positions, time_scale=1.0, capture_dir=None, *, daemon):
    """A network of robots at `positions` running AODV daemon `daemon` (python or cpp)."""
    name = "ta" + uuid.uuid4().hex[:6]
    spec = NetworkSpec(
        name=name,
        positions=tuple(positions),
        comm_range=10.0,
        routing="aodv",
        time_scale=time_scale,
        capture_dir=capture_dir,
        aodv_daemon=daemon,
    )
    try:
        with Network(spec) as net:
            wait_ready(net, len(positions))
            yield net
    finally:
        destroy(name)


def daemon_argv(daemon: str, *args: str) -> list[str]:
    """The command line of AODV daemon `daemon` (python or cpp) with `args`: the same
    arguments for both (topology.routing.aodv_command)."""
    return [*routing.aodv_command(daemon), *args]


def daemon(net, k):
    """The live AODV daemon of robot k (the newest, if it was restarted)."""
    proc = net.process(k, "aodv")
    assert proc is not None, f"no AODV daemon for robot {k}"
    return proc


def wait_ready(net, n, timeout=30.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if all(os.path.exists(stats_path(net, k)) for k in range(1, n + 1)):
            return
        for k in range(1, n + 1):
            assert daemon(net, k).poll() is None, open(f"{net.state_dir}/r{k}.aodv.log").read()
        time.sleep(0.05)
    raise AssertionError("AODV daemons did not start")


def stats_path(net, k):
    return f"{net.state_dir}/r{k}.aodv.json"


def stats(net, k):
    """Fresh statistics (SIGUSR1 makes the daemon rewrite its file), as the file holds them."""
    return read_fresh(stats_path(net, k), daemon(net, k)).to_json()


def routes(net, k):
    out = net.exec(k, ["ip", "-4", "route", "show", "proto", "101"], capture_output=True, text=True)
    return {line.split()[0]: line for line in out.stdout.splitlines() if "/" not in line.split()[0]}


def ping(net, k, dst, *args, timeout=30):
    return net.exec(
        k, ["ping", "-n", *args, dst], capture_output=True, text=True, timeout=timeout
    ).stdout


def test_chain_ping_4_hops_pcap_and_nng(aodv_daemon):
    with tempfile.TemporaryDirectory(prefix="ta-aodv-") as cap:
        _chain_ping_4_hops_pcap_and_nng(cap, aodv_daemon)


def _chain_ping_4_hops_pcap_and_nng(cap, aodv_daemon):
    with aodv_net(CHAIN5, 1.0, cap, daemon=aodv_daemon) as net:
        assert "10.0.0.5" not in routes(net, 1)
        out = ping(net, 1, "10.0.0.5", "-c", "2", "-W", "5")
        assert " 0% packet loss" in out, out
        ttls = {int(t) for t in re.findall(r"ttl=(\d+)", out)}
        assert ttls == {64 - 3}, out  # 4 hops: three routers decrement the TTL
        assert "via 10.0.0.2" in routes(net, 1)["10.0.0.5"]
        s1 = stats(net, 1)
        assert s1["discoveries_ok"] == 1 and s1["messages_sent"]["RREQ"] >= 1

        # A nanomsg-protocol message (pynng Pair0 over TCP) crosses the same 4 hops.
        server = net.spawn(
            5,
            [PY, "-c", textwrap.dedent("""
                import pynng
                with pynng.Pair0(listen="tcp://10.0.0.5:5555", recv_timeout=20000) as s:
                    s.send(b"pong:" + s.recv())
            """)],
            role="test",
            cwd=REPO,
        )  # fmt: skip
        time.sleep(0.5)
        client = net.exec(
            1,
            [PY, "-c", textwrap.dedent("""
                import pynng
                with pynng.Pair0(dial="tcp://10.0.0.5:5555", recv_timeout=10000) as s:
                    s.send(b"ping")
                    print(s.recv().decode())
            """)],
            capture_output=True, text=True, timeout=30, cwd=REPO,
        )  # fmt: skip
        assert client.stdout.strip() == "pong:ping", client.stderr
        server.wait(timeout=10)
    # The network is down: each tcpdump drained its queue and stopped; the pcaps are whole.

    # tshark decodes what crossed wlan0 as AODV with the expected fields.
    fields = ["aodv.type", "aodv.flags", "aodv.hopcount", "aodv.dest_ip", "aodv.orig_ip",
              "aodv.dest_seqno", "aodv.orig_seqno", "ip.ttl", "ip.dst"]  # fmt: skip
    rows = []
    for k in (1, 5):
        out = subprocess.run(
            ["tshark", "-r", f"{cap}/r{k}.pcap", "-Y", "aodv", "-T", "fields",
             *sum((["-e", f] for f in fields), [])],
            capture_output=True, text=True, check=True,
        ).stdout  # fmt: skip
        rows += [dict(zip(fields, line.split("\t"), strict=False)) for line in out.splitlines()]
    rreqs = [r for r in rows if r["aodv.type"] == "1" and r["aodv.orig_ip"] == "10.0.0.1"]
    assert rreqs and all(r["ip.dst"] == "255.255.255.255" for r in rreqs)
    first = rreqs[0]
    assert first["ip.ttl"] == "2" and first["aodv.hopcount"] == "0"  # TTL_START 2
    # tshark shows the 16 bits after Type: G (0x2000) and U (0x0800) set.
    assert int(first["aodv.flags"], 0) & 0x2800 == 0x2800
    assert first["aodv.orig_seqno"] == "1" and first["aodv.dest_seqno"] == "0"
    # The RREQ that reaches 5 (seen in r5.pcap, sent by 4) has hop count 3.
    assert any(r["aodv.type"] == "1" and r["aodv.hopcount"] == "3" for r in rows)
    # The RREP that reaches 1 has hop count 3 and comes from the destination 5.
    rreps = [
        r for r in rows
        if r["aodv.type"] == "2"
        and r["aodv.dest_ip"] == "10.0.0.5"
        and r["ip.dst"] == "10.0.0.1"
    ]  # fmt: skip
    assert rreps and rreps[0]["aodv.hopcount"] == "3"
    # HELLOs: RREPs to the broadcast address with IP TTL 1.
    hellos = [r for r in rows if r["aodv.type"] == "2" and r["ip.dst"] == "255.255.255.255"]
    assert hellos and all(h["ip.ttl"] == "1" and h["aodv.hopcount"] == "0" for h in hellos)


def test_link_cut_gives_rerr_and_traffic_takes_the_other_path(aodv_daemon):
    # 1 - 2 - 3 - 4 in a line; 5 sits above 2 and 3 and offers a detour 2 - 5 - 3.
    positions = [(0, 0), (8, 0), (16, 0), (24, 0), (12, 6)]
    with aodv_net(positions, time_scale=5.0, daemon=aodv_daemon) as net:
        out = ping(net, 1, "10.0.0.4", "-c", "1", "-W", "5")
        assert "ttl=62" in out, out  # 3 hops
        pinger = net.spawn(
            1, ["ping", "-n", "-i", "0.05", "-c", "120", "-W", "1", "10.0.0.4"],
            role="test", stdout=subprocess.PIPE, text=True,
        )  # fmt: skip
        time.sleep(2.0)
        net.move(3, (19.0, 3.0))  # 2 - 3 now 11.4 m apart; 3 - 4 and 5 - 3 stay linked
        assert (2, 3) not in net.links() and (3, 5) in net.links() and (3, 4) in net.links()
        text, _ = pinger.communicate(timeout=30)
        replies = [(int(s), int(t)) for s, t in re.findall(r"icmp_seq=(\d+) ttl=(\d+)", text)]
        assert {t for _, t in replies} == {62, 61}, text  # 3 hops before, 4 hops after
        last_short = max(s for s, t in replies if t == 62)
        first_long = min(s for s, t in replies if t == 61)
        assert first_long > last_short
        assert len([s for s, t in replies if t == 61]) > 30
        # Node 2 lost its next hop 3 and repaired the route locally (RFC 6.12) through 5;
        # the new way is longer, so it told its precursor 1 with a RERR with the N flag,
        # which leaves 1's route in place: 1 never had to discover 4 again.
        s2, s1 = stats(net, 2), stats(net, 1)
        assert s2["local_repairs"].get("ok", 0) >= 1, s2["local_repairs"]
        assert s2["messages_sent"].get("RERR", 0) >= 1
        assert s1["messages_received"].get("RERR", 0) >= 1
        assert [d["dest"] for d in s1["discoveries"]].count("10.0.0.4") == 1


def test_unknown_destination_icmp_unreachable_others_unaffected(aodv_daemon):
    with aodv_net(CHAIN5[:3], time_scale=10.0, daemon=aodv_daemon) as net:
        good = net.spawn(
            1, ["ping", "-n", "-i", "0.1", "-c", "40", "-W", "2", "10.0.0.3"],
            role="test", stdout=subprocess.PIPE, text=True,
        )  # fmt: skip
        out = ping(net, 1, "10.0.0.99", "-c", "1", "-W", "10")
        assert "Destination Host Unreachable" in out, out
        s1 = stats(net, 1)
        failed = [d for d in s1["discoveries"] if not d["ok"]]
        assert failed and failed[0]["dest"] == "10.0.0.99"
        # Ring search TTL 2, 4, 6, then NET_DIAMETER with RREQ_RETRIES = 2 and binary
        # exponential backoff: 21.0 s at time scale 1, so 2.1 s here, from the first RREQ
        # to giving up as the daemon measured it (not ping's start-up: under load that
        # took seconds). Timers never fire early; late ones (load) add little.
        assert 2.1 * 0.99 < failed[0]["latency_s"] < 6.0, failed[0]
        assert s1["icmp_unreachable_sent"] >= 1
        text, _ = good.communicate(timeout=30)
        assert " 0% packet loss" in text, text


def test_idle_route_expires_active_route_stays(aodv_daemon):
    with aodv_net(CHAIN5[:4], time_scale=5.0, daemon=aodv_daemon) as net:
        assert " 0% packet loss" in ping(net, 1, "10.0.0.4", "-c", "1", "-W", "5")
        # The pinger keeps the route to 3 in use: at real-time priority 1, as the daemons, so
        # that a loaded machine does not starve it past ACTIVE_ROUTE_TIMEOUT (0.6 s here), after
        # which the route would rightly go idle (seen once beside another whole suite).
        pinger = net.spawn(
            1,
            ["chrt", "-r", "1", "ping", "-n", "-i", "0.05", "10.0.0.3"],
            role="test",
            stdout=subprocess.DEVNULL,
        )
        # Until the pinger found 3 (spawning it may take a while on a loaded machine).
        deadline = time.monotonic() + 20
        while "10.0.0.3" not in routes(net, 1) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert "10.0.0.3" in routes(net, 1)
        # MY_ROUTE_TIMEOUT is 11.2 s, 2.24 s at time scale 5: the idle route to 4 goes from
        # the kernel then, while the used one to 3 is refreshed through the nftables set
        # and stays.
        deadline = time.monotonic() + 20
        while "10.0.0.4" in (r1 := routes(net, 1)) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert "10.0.0.4" not in r1, r1  # idle: gone from the kernel
        time.sleep(1.0)  # and some time after, the used route is still there
        assert "10.0.0.3" in routes(net, 1), routes(net, 1)
        assert pinger.poll() is None
        pinger.terminate()
        pinger.wait(timeout=10)


FUZZER = textwrap.dedent("""
    import random, socket, sys, time
    sys.path.insert(0, sys.argv[1])
    from aodv import packet as wire
    import ipaddress
    NET = ipaddress.IPv4Network("10.0.0.0/16")
    rng = random.Random(654)
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_BINDTODEVICE, b"wlan0")
    s.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
    def acceptable(raw):
        try:
            m = wire.decode(raw)
        except wire.MalformedPacket:
            return False
        addrs = [getattr(m, a) for a in ("dest", "orig") if hasattr(m, a)]
        addrs += [a for a, _ in getattr(m, "unreachable", ())]
        return all(ipaddress.IPv4Address(a) in NET for a in addrs)
    sent = skipped = 0
    valid = [bytes.fromhex(h) for h in sys.argv[2:]]
    while sent < 100000:
        kind = rng.random()
        if kind < 0.5:
            raw = rng.randbytes(rng.randrange(0, 64))
        elif kind < 0.8:
            base = rng.choice(valid)
            raw = base[: rng.randrange(len(base))]  # truncated
        else:
            raw = bytearray(rng.choice(valid))
            raw[0] = rng.choice([0, 5, 6, 17, 255])  # unknown type
            raw = bytes(raw)
        if acceptable(raw):
            skipped += 1
            continue
        s.sendto(raw, ("255.255.255.255", 654))
        sent += 1
        if sent % 200 == 0:
            time.sleep(0.01)
    print(sent, skipped)
""")


def test_fuzzed_datagrams_are_counted_and_change_nothing(aodv_daemon):
    with aodv_net(CHAIN5[:3], daemon=aodv_daemon) as net:
        assert " 0% packet loss" in ping(net, 2, "10.0.0.3", "-c", "1", "-W", "5")
        # Keep 2's one route in use so that its table is stable while it is fuzzed.
        keep = net.spawn(2, ["ping", "-n", "-i", "0.2", "10.0.0.3"], role="test",
                         stdout=subprocess.DEVNULL)  # fmt: skip
        # The discovery's RREQ (TTL 2) came back from 1 and made a route to 1, unused: let
        # it expire (ACTIVE_ROUTE_TIMEOUT) before taking the table that must not change.
        deadline = time.monotonic() + 10
        while "10.0.0.1" in routes(net, 2) and time.monotonic() < deadline:
            time.sleep(0.2)
        before = routes(net, 2)
        udp_before = net.exec(2, ["cat", "/proc/net/snmp"], capture_output=True, text=True).stdout
        valid = [
            wire.encode(wire.Rreq(1, "10.0.0.2", 0, "10.0.0.1", 1)).hex(),
            wire.encode(wire.Rrep("10.0.0.2", 1, "10.0.0.1", 6000)).hex(),
            wire.encode(wire.Rerr((("10.0.0.2", 1), ("10.0.0.3", 1)))).hex(),
        ]
        out = net.exec(
            1, [PY, "-c", FUZZER, REPO, *valid], capture_output=True, text=True, timeout=120
        )
        sent, skipped = map(int, out.stdout.split())
        assert sent == 100000, out.stderr
        assert skipped < 100
        # What the kernel itself dropped (socket buffer full) never reached the daemon.
        deadline = time.monotonic() + 30
        while True:
            udp_after = net.exec(2, ["cat", "/proc/net/snmp"], capture_output=True, text=True)
            lost = _udp_counter(udp_after.stdout, "RcvbufErrors") - _udp_counter(
                udp_before, "RcvbufErrors"
            )
            s2 = stats(net, 2)
            if s2["dropped"].get("malformed", 0) >= sent - lost or time.monotonic() > deadline:
                break
            time.sleep(0.3)
        assert daemon(net, 2).poll() is None
        # The kernel's RcvbufErrors may count a datagram the daemon still got: allow that.
        assert sent - lost <= s2["dropped"]["malformed"] <= sent
        assert lost < sent // 10
        assert s2["dropped"].get("error", 0) == 0
        assert routes(net, 2) == before, (before, routes(net, 2))
        assert " 0% packet loss" in ping(net, 2, "10.0.0.3", "-c", "1", "-W", "5")
        keep.terminate()
        keep.wait(timeout=5)


def _udp_counter(snmp: str, name: str) -> int:
    lines = [line.split() for line in snmp.splitlines() if line.startswith("Udp:")]
    header, values = lines[0], lines[1]
    return int(values[header.index(name)])


def test_sigterm_writes_stats_and_leaves_no_kernel_state(aodv_daemon):
    with aodv_net(CHAIN5[:2], daemon=aodv_daemon) as net:
        assert " 0% packet loss" in ping(net, 1, "10.0.0.2", "-c", "1", "-W", "5")
        proc = daemon(net, 1)
        assert routes(net, 1)
        proc.terminate()
        assert proc.wait(timeout=10) == 0
        final = DaemonStats.read(stats_path(net, 1)).to_json()
        assert final["robot"] == "r1" and final["discoveries_ok"] == 1
        assert final["messages_sent"]["RREQ"] >= 1 and final["bytes_sent"] > 0
        assert routes(net, 1) == {}
        links = net.exec(1, ["ip", "-o", "link"], capture_output=True, text=True).stdout
        assert "aodv0" not in links
        nft = net.exec(1, ["nft", "list", "tables"], capture_output=True, text=True).stdout
        assert "aodv" not in nft
        log = open(f"{net.state_dir}/r1.aodv.log").read()
        assert all(line.startswith("r1 ") for line in log.splitlines() if line.strip())


def test_forwarded_packet_without_route_draws_rerr_and_rediscovery(aodv_daemon):
    with aodv_net(CHAIN5[:3], daemon=aodv_daemon) as net:
        assert " 0% packet loss" in ping(net, 1, "10.0.0.3", "-c", "1", "-W", "5")
        # Robot 2's daemon restarts cleanly: its routes are gone, 1 and 3 still use it.
        old = daemon(net, 2)
        old.terminate()
        assert old.wait(timeout=10) == 0
        os.remove(stats_path(net, 2))
        net.spawn(
            2, daemon_argv(aodv_daemon, "--robot", "r2", "--stats", stats_path(net, 2)),
            role="aodv", cwd=REPO, stderr=subprocess.DEVNULL,
        )  # fmt: skip
        while not os.path.exists(stats_path(net, 2)):
            time.sleep(0.05)
        out = ping(net, 1, "10.0.0.3", "-c", "3", "-i", "0.3", "-W", "3")
        s2, s1 = stats(net, 2), stats(net, 1)
        # RFC 6.11 (ii): 2 gets data for 3 with no route and says so with a RERR.
        assert s2["messages_sent"].get("RERR", 0) >= 1
        assert s1["messages_received"].get("RERR", 0) >= 1
        assert s1["discoveries_ok"] >= 2  # the RERR made 1 discover the route again
        assert "ttl=63" in out, out


def restart_daemon(net, k, words, *extra, daemon):
    """Start robot k's daemon `daemon` again (time scale 10) and read its log until it is up;
    returns the process and whether a line said `words` on the way."""
    os.remove(stats_path(net, k))
    new = net.spawn(
        k, daemon_argv(daemon, "--robot", f"r{k}", "--time-scale", "10",
                       "--stats", stats_path(net, k), *extra),
        role="aodv", cwd=REPO, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    deadline = time.monotonic() + 20
    line, logged = "", False
    while "AODV up" not in line and time.monotonic() < deadline:
        line = new.stderr.readline()
        logged |= words in line
    return new, logged


def test_restart_after_crash_applies_the_reboot_rule(aodv_daemon):
    # Time scale 10: DELETE_PERIOD is 1.5 s.
    with aodv_net(CHAIN5[:2], time_scale=10.0, daemon=aodv_daemon) as net:
        assert " 0% packet loss" in ping(net, 1, "10.0.0.2", "-c", "1", "-W", "5")
        old = daemon(net, 2)
        old.kill()  # no teardown: its routes stay in the kernel
        old.wait(timeout=5)
        assert routes(net, 2)
        new, logged = restart_daemon(net, 2, "reboot rule", daemon=aodv_daemon)
        assert logged
        t_up = time.monotonic()
        deadline = t_up + 10
        while "10.0.0.2" in routes(net, 1) and time.monotonic() < deadline:
            time.sleep(0.05)  # 1's old route to 2 times out (HELLO loss, lifetime)
        t_ping = time.monotonic()
        assert t_ping < t_up + 1.3, "too slow to test the wait"
        out = ping(net, 1, "10.0.0.2", "-c", "8", "-i", "0.4", "-W", "5")
        replies = [
            (int(q), float(t) / 1000)
            for q, t in re.findall(r"icmp_seq=(\d+) ttl=\d+ time=([\d.]+) ms", out)
        ]
        assert replies, out
        # 1's RREQs reach 2 from the start; 2 answers only once DELETE_PERIOD (1.5 s) is
        # over, so no reply can come earlier (0.1 s of slack for reading the clocks).
        for seq, rtt in replies:
            assert t_ping + 0.4 * (seq - 1) + rtt >= t_up + 1.5 - 0.1, (t_ping - t_up, out)
        s2 = stats(net, 2)
        assert s2["messages_received"].get("RREQ", 0) >= 2
        new.terminate()
        new.wait(timeout=10)


GHOST_RREQ = textwrap.dedent("""
    # A RREQ from an address nobody holds (argv 2), sent as a raw IP datagram to argv 3.
    import socket, struct, sys
    sys.path.insert(0, sys.argv[1])
    from aodv import packet as wire
    src, dst = sys.argv[2], sys.argv[3]
    body = wire.encode(wire.Rreq(1, dst, 0, src, 1))
    udp = struct.pack("!HHHH", 654, 654, 8 + len(body), 0) + body
    ip = struct.pack("!BBHHHBBH4s4s", 0x45, 0, 20 + len(udp), 1, 0, 64, 17, 0,
                     socket.inet_aton(src), socket.inet_aton(dst))
    s = socket.socket(socket.AF_INET, socket.SOCK_RAW, socket.IPPROTO_RAW)
    s.sendto(ip + udp, (dst, 0))
""")


def test_a_reply_the_kernel_could_not_transmit_is_counted_as_such(aodv_daemon):
    """Robot 2 answers a RREQ from a neighbour that is gone before the RREP leaves (robot 1
    sends it from an address nobody holds): ARP for it fails, the kernel reports the RREP
    back to the daemon (IP_RECVERR), and the daemon counts it as sent but not transmitted,
    which is what robot 2's capture shows."""
    ghost = "10.0.0.77"
    with tempfile.TemporaryDirectory(prefix="ta-aodv-") as cap:
        with aodv_net(CHAIN5[:2], 1.0, cap, daemon=aodv_daemon) as net:
            assert " 0% packet loss" in ping(net, 1, "10.0.0.2", "-c", "1", "-W", "5")
            replies = stats(net, 2)["messages_sent"]["RREP"]
            net.exec(1, [PY, "-c", GHOST_RREQ, REPO, ghost, "10.0.0.2"], check=True, timeout=30)
            deadline = time.monotonic() + 15  # ARP gives up after 3 probes 1 s apart
            while True:
                s2 = stats(net, 2)
                if s2["messages_not_transmitted"].get("RREP") or time.monotonic() > deadline:
                    break
                time.sleep(0.5)
            assert s2["messages_sent"]["RREP"] == replies + 1
            assert s2["messages_not_transmitted"] == {"RREP": 1}
            assert s2["bytes_not_transmitted"] == 20
            assert s2["dropped"].get("send_failed", 0) == 0
            assert daemon(net, 2).poll() is None
        out = subprocess.run(
            ["tshark", "-r", os.path.join(cap, "r2.pcap"), "-Y", f"aodv && ip.dst == {ghost}"],
            capture_output=True, text=True, check=True,
        )  # fmt: skip
        assert out.stdout.strip() == ""  # it never reached wlan0


def test_clean_restart_waits_delete_period_and_resumes_its_numbers(aodv_daemon):
    """RFC 6.13 after a clean exit: no routes are left in the kernel, but the counter file the
    topology gives every daemon (--state) says this is a restart."""
    with aodv_net(CHAIN5[:3], time_scale=10.0, daemon=aodv_daemon) as net:  # DELETE_PERIOD 1.5 s
        assert " 0% packet loss" in ping(net, 1, "10.0.0.3", "-c", "2", "-W", "5")
        state = f"{net.state_dir}/r1.aodv.state"
        with open(state) as f:
            marks_before = json.load(f)
        old = daemon(net, 1)
        old.terminate()
        assert old.wait(timeout=10) == 0
        assert routes(net, 1) == {}  # a clean exit: nothing for the old rule to find
        new, logged = restart_daemon(net, 1, "restarted", "--state", state, daemon=aodv_daemon)
        assert logged
        t_up = time.monotonic()
        out = ping(net, 1, "10.0.0.3", "-c", "1", "-W", "5")
        t_reply = time.monotonic()
        assert " 0% packet loss" in out, out
        # No RREQ before DELETE_PERIOD: the reply cannot come earlier (0.1 s of slack).
        assert t_reply >= t_up + 1.5 - 0.1, t_reply - t_up
        s1 = stats(net, 1)
        (done,) = [d for d in s1["discoveries"] if d["dest"] == "10.0.0.3"]
        # The RREQ that went out after the wait was new to the neighbours (its ID above
        # every one used before): answered at its first try.
        assert done["ok"] and done["round_latency_s"] < 0.3, done
        with open(state) as f:
            marks_after = json.load(f)
        assert marks_after["seq"] > marks_before["seq"]
        assert marks_after["rreq_id"] > marks_before["rreq_id"]
        new.terminate()
        new.wait(timeout=10)


HOSTILE = textwrap.dedent("""
    # 100k datagrams at robot 2: half structurally valid AODV messages with extreme field
    # values, RREQs from 10k forged originators among them; half malformed.
    import random, socket, struct, sys, time
    sys.path.insert(0, sys.argv[1])
    from aodv import packet as wire
    rng = random.Random(3561)
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_BINDTODEVICE, b"wlan0")
    s.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
    FORGED = [f"10.0.{1 + i // 250}.{1 + i % 250}" for i in range(10000)]
    EXTREME32 = [0, 1, 0x7FFFFFFF, 0x80000000, 0xFFFFFFFE, 0xFFFFFFFF]
    HOPS = [0, 1, 34, 35, 254, 255]
    def addr():
        return rng.choice(["10.0.0.1", "10.0.0.2", "10.0.0.3", rng.choice(FORGED)])
    def u32():
        return rng.choice(EXTREME32) if rng.random() < 0.7 else rng.getrandbits(32)
    def extension():
        if rng.random() < 0.8:
            return b""
        body = rng.randbytes(rng.choice([0, 4, 9]))
        return bytes((rng.randrange(1, 256), len(body))) + body
    def valid():
        k = rng.random()
        if k < 0.45:
            m = wire.Rreq(u32(), addr(), u32(), rng.choice(FORGED), u32(), rng.choice(HOPS),
                          *(rng.random() < 0.5 for _ in range(5)))
        elif k < 0.75:
            hello = rng.random() < 0.3
            a = "10.0.0.1" if hello else addr()
            m = wire.Rrep(a, u32(), a if hello else addr(), u32(),
                          0 if hello else rng.choice(HOPS), False, rng.random() < 0.5, 0,
                          rng.choice([0, 1, 1000, 0xFFFFFFFF]) if hello else None)
        elif k < 0.95:
            dests = tuple((addr(), u32()) for _ in range(rng.choice([1, 2, 17, 255])))
            m = wire.Rerr(dests, rng.random() < 0.5)
        else:
            m = wire.RrepAck()
        return m.encode() + extension()
    n = int(sys.argv[2])
    for i in range(n):
        if i % 2:
            raw = valid()
        else:
            raw = valid()
            if rng.random() < 0.5:
                raw = raw[: rng.randrange(len(raw))]  # truncated
            else:
                raw = bytes([rng.choice([0, 5, 17])]) + raw[1:]  # unknown type
        s.sendto(raw, ("255.255.255.255", 654))
        if i % 500 == 0:
            time.sleep(0.02)
    print(n)
""")


def _rss_kb(pid: int) -> int:
    with open(f"/proc/{pid}/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("VmRSS:"))


RSS_BOUND_MB = 48  # the daemon's resident memory under the flood (17 MB idle, 19 MB peak here)


def test_hostile_flood_keeps_the_daemon_up_bounded_and_in_step_with_the_kernel(aodv_daemon):
    with aodv_net(CHAIN5[:3], daemon=aodv_daemon) as net:
        assert " 0% packet loss" in ping(net, 2, "10.0.0.3", "-c", "1", "-W", "5")
        proc = daemon(net, 2)
        rss_idle = _rss_kb(proc.pid)
        sender = net.spawn(1, [PY, "-c", HOSTILE, REPO, "100000"], role="test",
                           stdout=subprocess.PIPE, text=True, cwd=REPO)  # fmt: skip
        peak = rss_idle
        while sender.poll() is None:
            peak = max(peak, _rss_kb(proc.pid))
            time.sleep(0.2)
        assert sender.stdout.read().strip() == "100000"
        # Let the daemon drain its socket, then check the kernel against its table: no
        # route is added any more, only deleted, so kernel-before >= table >= kernel-after.
        deadline = time.monotonic() + 60
        received = -1
        while time.monotonic() < deadline:
            s2 = stats(net, 2)
            total = sum(s2["messages_received"].values()) + sum(s2["dropped"].values())
            if total == received:
                break
            received = total
            peak = max(peak, _rss_kb(proc.pid))
            time.sleep(0.5)
        assert proc.poll() is None, "the daemon died"
        kernel_before = set(routes(net, 2))
        table = set(stats(net, 2)["routes"])
        kernel_after = set(routes(net, 2))
        assert kernel_after <= table <= kernel_before, (table ^ kernel_before, table ^ kernel_after)
        s2 = stats(net, 2)
        assert s2["dropped"].get("error", 0) == 0 and s2["dropped"].get("encode_failed", 0) == 0
        assert s2["dropped"].get("malformed", 0) > 10000
        pd = s2["protocol_dropped"]
        assert pd.get("hop_count", 0) > 0 and pd.get("rreq_forward_ratelimit", 0) > 0, pd
        assert len(table) <= 1024  # Params.route_table_limit
        assert peak < RSS_BOUND_MB * 1024, f"peak RSS {peak / 1024:.0f} MB"
        # Once the forged routes have expired, kernel and table are equal, and work.
        deadline = time.monotonic() + 60
        while set(routes(net, 2)) != set(stats(net, 2)["routes"]):
            assert time.monotonic() < deadline, (routes(net, 2), stats(net, 2)["routes"])
            time.sleep(0.5)
        assert " 0% packet loss" in ping(net, 2, "10.0.0.3", "-c", "1", "-W", "5")
        print(f"RSS idle {rss_idle / 1024:.1f} MB, peak {peak / 1024:.1f} MB; {pd}")


def _exe(pid: int) -> str:
    return os.path.realpath(f"/proc/{pid}/exe")


def test_net_up_starts_the_daemon_asked_for_and_says_so(aodv_daemon):
    """`testbed net up --aodv-daemon` reaches the namespaces: every robot's daemon is the
    program asked for (the compiled one exec'd, the Python one forked from the fork server)."""
    name = "tcw" + uuid.uuid4().hex[:6]
    try:
        up = subprocess.run(
            [PY, "-m", "testbed", "net", "up", name, "--robots", "3", "--comm-range", "10",
             "--aodv-daemon", aodv_daemon],
            capture_output=True, text=True, timeout=120, cwd=REPO,
        )  # fmt: skip
        assert up.returncode == 0, up.stderr
        assert f"  AODV daemon: {aodv_daemon} ({aodv_daemon}: asked for)" in up.stdout, up.stdout
        st = state.read(name)
        assert st is not None
        pids = {p.robot: p.pid for p in st.processes if p.role == "aodv"}
        assert sorted(pids) == [1, 2, 3]
        program = routing.aodv_binary() if aodv_daemon == "cpp" else sys.executable
        assert {_exe(pid) for pid in pids.values()} == {os.path.realpath(program)}
        ping = subprocess.run(
            [PY, "-m", "testbed", "net", "exec", name, "r1", "--", "ping", "-n", "-c", "1",
             "-W", "5", "10.0.0.3"],
            capture_output=True, text=True, timeout=60, cwd=REPO,
        )  # fmt: skip
        assert " 0% packet loss" in ping.stdout, ping.stdout + ping.stderr
    finally:
        destroy(name)


def test_a_run_records_which_daemon_ran_and_why(aodv_daemon, tmp_path, small_map):
    name = "tcw" + uuid.uuid4().hex[:6]
    out = tmp_path / "run"
    try:
        run = subprocess.run(
            [PY, "-m", "testbed", "run", "--robots", "2", "--comm-range", "10",
             "--laser-range", "2", "--map", small_map, "--max-steps", "30", "--time-scale",
             "2", "--aodv-daemon", aodv_daemon, "--name", name, "--quiet", "--out", str(out)],
            capture_output=True, text=True, timeout=300, cwd=REPO,
        )  # fmt: skip
    finally:
        destroy(name)
    with open(out / "result.json") as f:
        result = json.load(f)
    # 30 steps: the step cap ends it (exit status 1 says the run did not finish exploring).
    assert (run.returncode, result["status"]) == (1, "step_cap"), run.stderr
    assert result["aodv_daemon"] == aodv_daemon
    assert result["aodv_daemon_reason"] == f"{aodv_daemon}: asked for"
    assert result["config"]["extra"]["aodv_daemon"] == aodv_daemon
    # The daemons ran and wrote their statistics, read back as the Python daemon's.
    for k in (1, 2):
        s = DaemonStats.read(str(out / "aodv" / f"r{k}.json")).to_json()
        assert s["robot"] == f"r{k}" and s["messages_sent"].get("HELLO", 0) >= 1


def test_stats_period_zero_writes_when_ready_asked_and_stopping(aodv_daemon):
    """--stats-period 0 (what `testbed run` gives the daemons unless --view shows them live):
    the statistics file is written once the daemon is ready, then only on SIGUSR1 and as it
    stops, never on a timer of its own."""
    name = "ta" + uuid.uuid4().hex[:6]
    spec = NetworkSpec(name=name, positions=CHAIN5[:2], comm_range=10.0, routing="aodv",
                       time_scale=5.0, aodv_daemon=aodv_daemon, aodv_stats_period=0.0)  # fmt: skip
    try:
        with Network(spec) as net:
            wait_ready(net, 2)
            path = stats_path(net, 1)
            ready = os.stat(path).st_mtime_ns
            time.sleep(2.5)  # HELLOs go out meanwhile; a period of 1 s would rewrite twice
            assert os.stat(path).st_mtime_ns == ready
            assert read_fresh(path, daemon(net, 1)).to_json()["robot"] == "r1"
            asked = os.stat(path).st_mtime_ns
            assert asked != ready
            time.sleep(0.05)  # past the file system's timestamp granularity
            proc = daemon(net, 1)
            proc.send_signal(signal.SIGTERM)
            assert proc.wait(timeout=10) == 0
            assert os.stat(path).st_mtime_ns != asked  # the final statistics
            assert DaemonStats.read(path).to_json()["robot"] == "r1"
    finally:
        destroy(name)


def test_netns_option_enters_the_namespace_before_anything_else(aodv_daemon, tmp_path):
    """`--netns NAME`: started in the host's namespace (no `ip netns exec`), the daemon makes
    its TUN device, routes and nftables table in robot 1's namespace, exactly the table
    aodv.kernel.UseMonitor's ruleset gives (tb-aodv sends it over netlink, not through nft),
    and nothing in the host's; a namespace that is not there is one line and status 2."""
    name = "ta" + uuid.uuid4().hex[:6]
    spec = NetworkSpec(name=name, positions=CHAIN5[:1], comm_range=10.0, routing="none")
    stats_file = tmp_path / "r1.json"
    try:
        with Network(spec) as net:
            ns = net.robot_ns(1)
            argv = daemon_argv(aodv_daemon, "--netns", ns, "--robot", "r1", "--stats",
                               str(stats_file), "--stats-period", "0")  # fmt: skip
            bad = subprocess.run(daemon_argv(aodv_daemon, "--netns", name + "-gone", "--robot",
                                             "r1"),
                                 capture_output=True, text=True, timeout=30, cwd=REPO)  # fmt: skip
            assert bad.returncode == 2, bad.stderr
            assert bad.stderr.count("\n") == 1 and f"{name}-gone" in bad.stderr, bad.stderr
            proc = subprocess.Popen(argv, stderr=subprocess.PIPE, text=True, cwd=REPO)
            try:
                deadline = time.monotonic() + 30
                while not stats_file.exists():
                    assert proc.poll() is None and time.monotonic() < deadline, proc.stderr
                    time.sleep(0.02)
                links = net.exec(1, ["ip", "-o", "link"], capture_output=True, text=True)
                assert "aodv0" in links.stdout
                host = subprocess.run(["ip", "-o", "link"], capture_output=True, text=True)
                assert "aodv0" not in host.stdout
                got = net.exec(1, ["nft", "list", "table", "ip", "aodv"],
                               capture_output=True, text=True, check=True).stdout  # fmt: skip
            finally:
                proc.terminate()
                assert proc.wait(timeout=10) == 0
            assert "aodv" not in net.exec(1, ["nft", "list", "tables"], capture_output=True,
                                          text=True).stdout  # fmt: skip
            # The reference: the Python daemon's ruleset through nft, in the same namespace.
            ruleset = _DryUseMonitor(ROBOT_IFACE, "10.0.0.0/16", 1.0).ruleset
            net.exec(1, ["nft", "-f", "-"], input=ruleset, text=True, check=True)
            want = net.exec(1, ["nft", "list", "table", "ip", "aodv"],
                            capture_output=True, text=True, check=True).stdout  # fmt: skip
            net.exec(1, ["nft", "delete", "table", "ip", "aodv"], check=True)
            assert got == want
    finally:
        destroy(name)


class _DryUseMonitor(UseMonitor):
    """aodv.kernel.UseMonitor's ruleset, without running nft."""

    def remove(self) -> None:
        pass

    @staticmethod
    def _nft(args: list[str], stdin: str | None = None) -> str:
        return ""
