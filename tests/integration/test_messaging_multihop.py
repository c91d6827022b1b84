"""Zenoh and DDS messengers over two hops of the emulated radio, in real namespaces.

Three robots in a chain, r1 - r2 - r3 (the range model links only neighbours), with static
/32 routes through r2 (no routing daemon: the routes are what AODV would install). A
messenger process runs in r1 and in r3 (tests/integration/messenger_probe.py), configured as
a robot configures it. r1's message reaches r3, and r2's kernel forwarded the traffic. Then
r3's process is killed: r1's sends keep returning within the send timeout, and fail once the
teammate is given up. Namespace names carry "mwz"; everything goes, also on failure.
"""

import json
import select
import subprocess
import sys
import time
import uuid

import pytest

from node.timing import RobotTimings
from testbed import PROJECT_ROOT
from topology import names
from topology.kernel import netns
from topology.network import Network, destroy
from topology.spec import NetworkSpec

PORTS = {"zenoh": 47450, "dds": 47460}  # DDS: UDP 47470 (discovery) and 47471 (data)
TEAM = 3
SLACK_S = 0.05  # scheduling on a loaded two-core machine
SEND_TIMEOUT_S = RobotTimings().goal_send_timeout_ms / 1000
LEASE_S = 4 * RobotTimings().goal_reconnect_max_ms / 1000  # both messengers' lease


@pytest.fixture(params=["zenoh", "dds"])
def kind(request) -> str:
    pytest.importorskip(
        {"zenoh": "zenoh", "dds": "cyclonedds"}[request.param],
        reason=f"the {request.param} middleware's Python package is not installed",
    )
    return request.param


@pytest.fixture
def chain():
    """r1 - r2 - r3 with routes through r2; torn down whatever happens."""
    name = "mwz" + uuid.uuid4().hex[:7]
    spec = NetworkSpec(name=name, positions=((0.0, 0.0), (5.0, 0.0), (10.0, 0.0)), comm_range=6.0)
    try:
        with Network(spec) as net:
            assert net.links() == {(1, 2), (2, 3)}
            a = names.robot_addr
            for k, direct, far in ((1, 2, 3), (3, 2, 1)):
                net.exec(k, ["ip", "route", "add", f"{a(direct)}/32", "dev", "wlan0"], check=True)
                net.exec(k, ["ip", "route", "add", f"{a(far)}/32", "via", a(direct), "dev",
                             "wlan0", "onlink"], check=True)  # fmt: skip
            for other in (1, 3):
                net.exec(2, ["ip", "route", "add", f"{a(other)}/32", "dev", "wlan0"], check=True)
            yield net
    finally:
        destroy(name)


class Probe:
    """A messenger process in one robot's namespace, spoken to over its stdio."""

    def __init__(self, net: Network, kind: str, k: int):
        self.proc = net.spawn(
            k, [sys.executable, f"{PROJECT_ROOT}/tests/integration/messenger_probe.py", kind,
                str(k), str(PORTS[kind]), str(TEAM)],
            role="test", stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
            cwd=PROJECT_ROOT, env={"PYTHONPATH": PROJECT_ROOT, "PATH": "/usr/bin:/bin"},
        )  # fmt: skip
        assert self.next_event(20.0) == {"up": True}

    def next_event(self, timeout: float) -> dict | None:
        if not select.select([self.proc.stdout], [], [], timeout)[0]:
            return None
        line = self.proc.stdout.readline()
        return json.loads(line) if line else None

    def send(self, j: int, text: str) -> dict:
        self.proc.stdin.write(f"send {j} {text}\n")
        self.proc.stdin.flush()
        while True:
            event = self.next_event(5.0)
            assert event is not None, "the probe did not answer a send"
            if "sent" in event:
                return event

    def received(self, timeout: float) -> list[str]:
        out, deadline = [], time.monotonic() + timeout
        while (event := self.next_event(max(0.0, deadline - time.monotonic()))) is not None:
            out.append(event["received"])
        return out


def _forwarded(ns: str) -> int:
    """Ip ForwDatagrams of namespace `ns`: packets its kernel routed on."""

    def read() -> int:
        with open("/proc/thread-self/net/snmp") as f:
            head, values = (line.split() for line in f if line.startswith("Ip:"))
        return int(values[head.index("ForwDatagrams")])

    return netns.run_in(ns, read)


def test_a_message_crosses_two_hops_and_a_dead_teammate_never_blocks_a_send(chain, kind):
    r1, r3 = Probe(chain, kind, 1), Probe(chain, kind, 3)
    forwarded0 = _forwarded(chain.robot_ns(2))
    # Until discovery has matched r3 (a send fails at once before), then one message.
    deadline = time.monotonic() + 15.0
    while not r1.send(3, "hello-r3")["ok"]:
        assert time.monotonic() < deadline, f"{kind}: r1 never reached r3"
        time.sleep(0.1)
    got = r3.received(3.0)
    assert "hello-r3" in got, f"{kind}: r3 received {got}"
    assert _forwarded(chain.robot_ns(2)) > forwarded0  # through r2's kernel
    back = r3.send(1, "hello-r1")
    assert back["ok"] and "hello-r1" in r1.received(3.0), back

    r3.proc.kill()
    r3.proc.wait()
    outcomes = []
    t0 = time.monotonic()
    while time.monotonic() - t0 < LEASE_S + 2.0:
        e = r1.send(3, "to-the-dead")
        outcomes.append(e)
        assert e["took"] <= SEND_TIMEOUT_S + SLACK_S, (kind, e)
        time.sleep(0.05)
    said = f"{kind}: {sum(e['ok'] for e in outcomes)} of {len(outcomes)} sends taken"
    assert not outcomes[-1]["ok"], said  # r3 given up: its session closed / lease expired
    r1.proc.stdin.close()
    assert r1.proc.wait(timeout=20) == 0  # close() returned and the process ended cleanly
