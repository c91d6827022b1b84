"""Routing metrics from real captures: two namespaces joined through a bridge namespace.

Robot 1 (10.0.0.1) and robot 2 (10.0.0.2) each have `wlan0`, a veth whose peer is a port of a
bridge in a third namespace, and tcpdump on `wlan0` as a run would have. The test sends known
AODV-shaped datagrams on UDP port 654 and a TCP stream from robot 1 to robot 2, with an nftables
rule in the bridge dropping every 5th TCP data frame, and checks the numbers computed from the
pcaps against what was sent, what the kernel counted and what nftables dropped.
"""

import json
import os
import shutil
import signal
import subprocess
import time
import uuid

import pytest

from testbed.analysis import pcapmetrics

pytestmark = pytest.mark.skipif(
    os.geteuid() != 0 or shutil.which("tcpdump") is None or shutil.which("tshark") is None,
    reason="needs root, tcpdump and tshark",
)

N_RREQ = 7  # broadcast from robot 1
N_HELLO = 4  # RREP to 255.255.255.255 with TTL 1, from robot 1
N_RREP = 5  # unicast from robot 2 to robot 1
TCP_BYTES = 200_000


def sh(*argv, ns=None, check=True, **kw):
    if ns:
        argv = ("ip", "netns", "exec", ns, *argv)
    return subprocess.run(argv, check=check, capture_output=True, text=True, **kw)


def tx_packets(ns):
    doc = json.loads(sh("ip", "-s", "-j", "link", "show", "wlan0", ns=ns).stdout)
    return doc[0]["stats64"]["tx"]["packets"]


SENDER = r"""
import socket, sys
kind = sys.argv[1]
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
s.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
s.setsockopt(socket.SOL_SOCKET, socket.SO_BINDTODEVICE, b"wlan0")
s.bind(("0.0.0.0", 654))
if kind == "rreq":
    for i in range(int(sys.argv[2])):
        s.sendto(bytes([1, 0, 0, 0]) + bytes(20), ("255.255.255.255", 654))
elif kind == "hello":
    s.setsockopt(socket.IPPROTO_IP, socket.IP_TTL, 1)
    for i in range(int(sys.argv[2])):
        s.sendto(bytes([2, 0, 0, 0]) + bytes(16), ("255.255.255.255", 654))
elif kind == "rrep":
    for i in range(int(sys.argv[2])):
        s.sendto(bytes([2, 0, 0, 0]) + bytes(16), ("10.0.0.1", 654))
"""

TCP_SERVER = r"""
import socket, sys
srv = socket.socket(); srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
srv.bind(("10.0.0.2", 5555)); srv.listen(1); print("ready", flush=True)
c, _ = srv.accept(); n = 0
while True:
    b = c.recv(65536)
    if not b: break
    n += len(b)
print(n, flush=True)
"""

TCP_CLIENT = r"""
import socket, sys, time
c = socket.create_connection(("10.0.0.2", 5555))
data = bytes(1000)
for i in range(int(sys.argv[1]) // 1000):
    c.sendall(data)
    time.sleep(0.0005)
c.close()
"""


@pytest.fixture
def bridged_pair(tmp_path):
    tag = uuid.uuid4().hex[:6]
    nss = {"m": f"ts{tag}-m", 1: f"ts{tag}-r1", 2: f"ts{tag}-r2"}
    try:
        for ns in nss.values():
            sh("ip", "netns", "add", ns)
            sh("sysctl", "-qw", "net.ipv6.conf.all.disable_ipv6=1", ns=ns)
            sh("sysctl", "-qw", "net.ipv6.conf.default.disable_ipv6=1", ns=ns)
            sh("ip", "link", "set", "lo", "up", ns=ns)
        m = nss["m"]
        sh("ip", "-n", m, "link", "add", "name", "br0", "type", "bridge")
        for k in (1, 2):
            sh("ip", "-n", m, "link", "add", "name", f"p{k}", "type", "veth", "peer", "name",
               "wlan0", "netns", nss[k])  # fmt: skip
            sh("ip", "-n", m, "link", "set", f"p{k}", "master", "br0", "up")
            sh("ip", "-n", nss[k], "addr", "add", f"10.0.0.{k}/24", "dev", "wlan0")
            sh("ip", "-n", nss[k], "link", "set", "wlan0", "up")
        sh("ip", "-n", m, "link", "set", "br0", "up")
        yield nss, tmp_path
    finally:
        for ns in nss.values():
            for pid in sh("ip", "netns", "pids", ns, check=False).stdout.split():
                try:
                    os.kill(int(pid), signal.SIGKILL)
                except ProcessLookupError:
                    pass
            sh("ip", "netns", "del", ns, check=False)


def start_capture(ns, path):
    # --immediate-mode: without it libpcap hands packets over in blocks with a 1 s timeout,
    # and stopping tcpdump loses the last block (up to a second of traffic).
    argv = ["tcpdump", "-i", "wlan0", "--immediate-mode", "-U", "-n", "-w", str(path)]
    p = subprocess.Popen(
        ["ip", "netns", "exec", ns, *argv],
        stderr=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        text=True,
    )
    line = p.stderr.readline()  # "listening on wlan0 ..." once the capture is open
    assert "listening" in line, line
    return p


def wait_until_written(path, quiet=0.5, timeout=10.0):
    """tcpdump drops what it has not read yet when it is stopped: on a loaded machine it can
    lag, so wait until the file has not grown for `quiet` seconds."""
    deadline = time.monotonic() + timeout
    size, since = -1, time.monotonic()
    while time.monotonic() < deadline:
        now_size = path.stat().st_size
        if now_size != size:
            size, since = now_size, time.monotonic()
        elif time.monotonic() - since >= quiet:
            return
        time.sleep(0.05)


DROP_RULE = """
table bridge ts {
    chain tsfw {
        type filter hook forward priority 0; policy accept;
        ip saddr 10.0.0.1 ip protocol tcp ip length > 100 numgen inc mod 5 == 0 counter drop
    }
}
"""


def test_metrics_from_real_pcaps(bridged_pair):
    nss, tmp = bridged_pair
    m = nss["m"]
    sh("nft", "-f", "-", ns=m, input=DROP_RULE)
    run = tmp / "run"
    (run / "pcaps").mkdir(parents=True)
    caps = {k: start_capture(nss[k], run / "pcaps" / f"r{k}.pcap") for k in (1, 2)}
    try:
        before = {k: tx_packets(nss[k]) for k in (1, 2)}
        server = subprocess.Popen(
            ["ip", "netns", "exec", nss[2], "python3", "-c", TCP_SERVER],
            stdout=subprocess.PIPE,
            text=True,
        )
        assert server.stdout.readline().strip() == "ready"
        sh("python3", "-c", SENDER, "rreq", str(N_RREQ), ns=nss[1])
        sh("python3", "-c", SENDER, "hello", str(N_HELLO), ns=nss[1])
        sh("python3", "-c", SENDER, "rrep", str(N_RREP), ns=nss[2])
        sh("python3", "-c", TCP_CLIENT, str(TCP_BYTES), ns=nss[1], timeout=60)
        received = int(server.stdout.readline())
        server.wait(timeout=10)
        time.sleep(0.3)
        after = {k: tx_packets(nss[k]) for k in (1, 2)}
    finally:
        for k in caps:
            wait_until_written(run / "pcaps" / f"r{k}.pcap")
        for p in caps.values():
            p.send_signal(signal.SIGINT)
            p.wait(timeout=10)
    assert received == TCP_BYTES
    ruleset = json.loads(sh("nft", "-j", "list", "table", "bridge", "ts", ns=m).stdout)
    rule = next(item["rule"] for item in ruleset["nftables"] if "rule" in item)
    counter = next(e["counter"] for e in rule["expr"] if "counter" in e)
    dropped = counter["packets"]
    # The counter counts IP bytes: payload + 20 (IP) + 32 (TCP with timestamps) per frame.
    dropped_payload = counter["bytes"] - 52 * dropped
    assert dropped > 0

    metrics = pcapmetrics.run_metrics(run).to_json()  # every key of routing.json
    r1, r2 = metrics["robots"]["r1"], metrics["robots"]["r2"]
    # Everything each robot transmitted, as the kernel counted it.
    assert r1["tx_packets"] == after[1] - before[1]
    assert r2["tx_packets"] == after[2] - before[2]
    # Routing control packets: exactly what was sent, by type; the ICMP port-unreachable
    # errors robot 1 sends back (quoting a UDP 654 header) are not AODV.
    assert r1["control_tx_packets"] == N_RREQ + N_HELLO
    assert r2["control_tx_packets"] == N_RREP
    assert r1["aodv_tx_by_type"] == {"RREQ": N_RREQ, "HELLO": N_HELLO}
    assert r2["aodv_tx_by_type"] == {"RREP": N_RREP}
    assert r1["control_tx_payload_bytes"] == 24 * N_RREQ + 20 * N_HELLO
    assert r1["control_rx_packets"] == N_RREP
    assert metrics["control_tx_packets"] == N_RREQ + N_HELLO + N_RREP
    total_tx = after[1] - before[1] + after[2] - before[2]
    assert metrics["overhead_packets"] == pytest.approx((N_RREQ + N_HELLO + N_RREP) / total_tx)
    # Delivery: TCP retransmits, so every unique segment arrives, but per transmission exactly
    # what the bridge dropped is missing. Robot 2 sends no data, only ACKs.
    assert metrics["segment_delivery"] == 1.0
    assert metrics["delivered_payload_bytes"] == TCP_BYTES
    assert metrics["tcp_transmissions"] - metrics["tcp_transmissions_delivered"] == dropped
    sent_payload = metrics["tcp_payload_bytes_transmitted"]
    assert sent_payload - metrics["tcp_payload_bytes_received"] == dropped_payload
    assert metrics["pdf"] == pytest.approx(1 - dropped_payload / sent_payload)
    assert 0 < metrics["delay_ms_median"] < 50
    assert metrics["throughput_bps"] > 0
    # The result is cached next to the pcaps and reused.
    assert (run / "routing.json").is_file()
    assert pcapmetrics.run_metrics(run).pdf == metrics["pdf"]
