"""TCP keeps emulated time: one transfer over a lossy link takes the same emulated time, with
as many retransmissions, at time scale 1 and at 10 (topology.kernel.nettimers, applied by the
namespace-making code of topology.network).

The transfer is what the robots' goal messages are: small messages, each answered, over one
connection, from robot 1 to robot 2 through the veth medium, with 10% of the frames from 1 to
2 dropped by the testbed's own nftables loss. A lost message waits for TCP's retransmission
timer, so the transfer's time is mostly those waits: at time scale 10 with the kernel's timers
on the wall clock each lasts ten times as long in emulated time (about 2 emulated seconds
instead of 0.2), and the transfer ten times as long.

Made robust for a loaded two-core machine: the loop runs at real-time priority (like the
world's step loop), so the time measured is the kernel's timers and not the scheduler's; the
loss starts after the handshake (a SYN's first timeout, 1 s, cannot be dilated: the record
says so); the comparison is of the emulated time per retransmission (the losses drawn differ
from run to run), within a factor of 1.5, and of the whole transfer, within a factor of 2;
the retransmissions are compared within four standard deviations of their difference. Without
dilation both ratios are about 10. About 15 s, most of it the run at time scale 1.
"""

import math
import os
import socket
import time

import pytest

from common.sched import deadline_priority
from topology import names
from topology.kernel import netns
from topology.network import Network
from topology.spec import Impairment, NetworkSpec

PORT = 47200
LOSS_PCT = 10.0
EXCHANGES = 500
MESSAGE = b"g" * 1000  # one segment, as a goal message is
ANSWER = b"a" * 64
RECV_TIMEOUT_S = 30.0  # a broken transfer fails the test instead of hanging it

HAS_RTO_SYSCTL = os.path.exists("/proc/sys/net/ipv4/tcp_rto_min_us")
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(
        not HAS_RTO_SYSCTL,
        reason="this kernel has no net.ipv4.tcp_rto_min_us (Linux 6.11 and later): TCP's "
        "retransmission timer cannot be dilated here (result.json's network_timers says so)",
    ),
]


def _routes(net: Network) -> None:
    """Static routes and neighbours: no routing daemon, and no ARP to lose."""
    macs = {
        k: net.exec(k, ["cat", "/sys/class/net/wlan0/address"], capture_output=True,
                    text=True, check=True).stdout.strip()
        for k in (1, 2)
    }  # fmt: skip
    for k, other in ((1, 2), (2, 1)):
        addr = names.robot_addr(other)
        net.exec(k, ["ip", "route", "add", f"{addr}/32", "dev", "wlan0", "scope", "link"],
                 check=True)  # fmt: skip
        net.exec(k, ["ip", "neigh", "replace", addr, "lladdr", macs[other], "dev", "wlan0",
                     "nud", "permanent"], check=True)  # fmt: skip


def _retransmitted(ns: str) -> int:
    """Tcp RetransSegs of namespace `ns` (/proc/thread-self/net: the reading thread's)."""

    def read() -> int:
        with open("/proc/thread-self/net/snmp") as f:
            head, values = (line.split() for line in f if line.startswith("Tcp:"))
        return int(values[head.index("RetransSegs")])

    return netns.run_in(ns, read)


def _recv_exactly(sock: socket.socket, n: int) -> None:
    got = 0
    while got < n:
        chunk = sock.recv(n - got)
        if not chunk:
            raise ConnectionError("the connection closed mid-transfer")
        got += len(chunk)


def transfer(name: str, scale: float) -> dict:
    """The transfer at time scale `scale`: emulated seconds, and the retransmissions of the
    sender (robot 1) and of the answering robot 2."""
    spec = NetworkSpec(name=name, positions=((0, 0), (5, 0)), comm_range=10.0, time_scale=scale)
    with Network(spec) as net:
        _routes(net)
        ns1, ns2 = net.robot_ns(1), net.robot_ns(2)
        server = netns.run_in(ns2, lambda: socket.create_server((names.robot_addr(2), PORT)))
        socks = [server]
        try:
            client = netns.run_in(
                ns1, lambda: socket.create_connection((names.robot_addr(2), PORT), timeout=5)
            )
            socks.append(client)
            peer, _ = server.accept()
            socks.append(peer)
            for s in (client, peer):
                s.settimeout(RECV_TIMEOUT_S)
                s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            # From robot 1 to robot 2 only, after the handshake.
            net.medium.impairer.apply(names.link_end(1, 2), Impairment(loss_pct=LOSS_PCT))
            sent0, answered0 = _retransmitted(ns1), _retransmitted(ns2)
            with deadline_priority(1, -10):
                t0 = time.monotonic()
                for _ in range(EXCHANGES):
                    client.sendall(MESSAGE)
                    _recv_exactly(peer, len(MESSAGE))
                    peer.sendall(ANSWER)
                    _recv_exactly(client, len(ANSWER))
                wall = time.monotonic() - t0
            return {
                "scale": scale,
                "emulated_s": wall * scale,
                "retransmissions": _retransmitted(ns1) - sent0,
                "answer_retransmissions": _retransmitted(ns2) - answered0,
                "rto_floor_us": netns.run_in(ns1, lambda: _sysctl("net.ipv4.tcp_rto_min_us")),
            }
        finally:
            for s in socks:
                s.close()


def _sysctl(key: str) -> int:
    with open("/proc/sys/" + key.replace(".", "/")) as f:
        return int(f.read())


def _line(r: dict) -> str:
    per = r["emulated_s"] / max(1, r["retransmissions"]) * 1000
    return (
        f"K={r['scale']:g}: {r['emulated_s']:.2f} emulated s, {r['retransmissions']} "
        f"retransmissions ({per:.0f} emulated ms each), RTO floor {r['rto_floor_us']} us, "
        f"{r['answer_retransmissions']} spurious retransmissions of answers"
    )


def test_a_lossy_transfer_takes_the_same_emulated_time_at_time_scale_1_and_10(tb_name):
    real = transfer(tb_name, 1.0)
    dilated = transfer(tb_name, 10.0)
    said = f"{_line(real)}; {_line(dilated)}"
    print(said)
    r1, r10 = real["retransmissions"], dilated["retransmissions"]
    # The loss was there: 500 messages at 10% lose about 55 (the retransmissions lost too).
    assert r1 >= 20 and r10 >= 20, said
    assert abs(r10 - r1) <= 4 * math.sqrt(r1 + r10), said
    per_real = real["emulated_s"] / r1
    per_dilated = dilated["emulated_s"] / r10
    assert 1 / 1.5 <= per_dilated / per_real <= 1.5, said
    assert 0.5 <= dilated["emulated_s"] / real["emulated_s"] <= 2.0, said
