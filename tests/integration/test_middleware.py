"""Each middleware (node.messaging) carrying a robot's message over the emulated network, and
what a send does once its teammate's process is dead.

Three robots in a line, 8 m apart with a 10 m radio range, over the AODV daemon: r1 and r3
are out of each other's range, so r1's messages to r3 go through r2 on a route found on
demand. A messenger runs alone in its robot's namespace (tests/integration/mwprobe.py), as
the robot would run it, and each middleware whose Python package is installed is tried
(one whose package is missing is skipped, with the registry's reason):

- a message sent from r1 arrives at r3;
- with r3's process killed, each of r1's sends returns within the send timeout (the
  measured times and the messenger's own blocked_max_s say so), and they come to fail:
  nanomsg and zeromq by TCP's FIN or RST (nanomsg after its buffer of 8), each failure
  having waited the timeout; Zenoh and DDS when r3's lease ends, each failure at once (no
  subscriber left), their sends until then taken and lost;
  zeromq-reqrep's send instead never returns (awaiting a reply from a dead process),
  shown by a send still inside after 15 send timeouts, in a child process then killed.

Last, one short `testbed run --middleware zeromq` team run on a small map, captured: it
finishes, its results carry the messenger's counters, and the captures' middleware class
agrees with them; and a short captured 2-robot run over Zenoh and over DDS each, whose
captures hold exactly the messages each robot sent and its teammate received (DDS's RTPS
walked as tshark's dissector reads it).
"""

import json
import os
import select
import subprocess
import sys
import time
import uuid

import cv2
import numpy as np
import pytest

from node import messaging
from testbed import PROJECT_ROOT
from testbed.analysis import pcapmetrics
from topology.names import robot_addr
from topology.network import Network, destroy
from topology.spec import NetworkSpec

PROBE = os.path.join(os.path.dirname(__file__), "mwprobe.py")
CHAIN = ((0.0, 0.0), (8.0, 0.0), (16.0, 0.0))
BASE_PORT = 5201
TIMEOUT_MS = 200
SLACK_S = 0.5  # a loaded two-core machine's scheduling, on top of the timeout
BLOCK_WAIT_S = 3.0  # 15 send timeouts: a bounded send would have returned long before
DELIVERY_WAIT_S = 45.0  # route discovery, TCP's first SYN retransmission (1 s), connect
# When a middleware gives a dead teammate up: Zenoh and DDS at the end of its lease, four
# redial ceilings (mwprobe.py: 4 x 500 ms); nanomsg and zeromq on TCP's FIN or RST.
LEASE_S = {"zenoh": 2.0, "dds": 2.0}
WAITS_THE_TIMEOUT = {"nanomsg", "zeromq"}  # their failed send waited for a connection


def _param(name: str):
    why = messaging.unavailable(name)
    return pytest.param(name, marks=pytest.mark.skipif(why is not None, reason=why or ""))


MIDDLEWARES = [_param(m) for m in messaging.MIDDLEWARES]
BOUNDED = [_param(m) for m in messaging.MIDDLEWARES if m != "zeromq-reqrep"]


@pytest.fixture(scope="module")
def chain():
    name = "mwc" + uuid.uuid4().hex[:5]
    spec = NetworkSpec(name=name, positions=CHAIN, comm_range=10.0, routing="aodv")
    try:
        with Network(spec) as net:
            _wait_aodv(net)
            yield net
    finally:
        destroy(name)


def _wait_aodv(net, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if all(os.path.exists(f"{net.state_dir}/r{k}.aodv.json") for k in (1, 2, 3)):
            return
        time.sleep(0.05)
    raise AssertionError("the AODV daemons did not start")


class Probe:
    """mwprobe.py in robot k's namespace, its output read line by line with a timeout."""

    def __init__(self, net, k: int, middleware: str, port: int, *mode: str):
        env = dict(os.environ, PYTHONPATH=PROJECT_ROOT)
        argv = [sys.executable, PROBE, middleware, str(k), str(port), str(TIMEOUT_MS), *mode]
        self.proc = net.spawn(k, argv, role="test", env=env, stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE)  # fmt: skip
        self.buf = b""
        assert self.line(20.0) == "ready", self.stderr()

    def line(self, timeout: float) -> str | None:
        deadline = time.monotonic() + timeout
        while b"\n" not in self.buf:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self.proc.stdout], [], [], left)[0]:
                return None
            chunk = os.read(self.proc.stdout.fileno(), 65536)
            if not chunk:
                return None
            self.buf += chunk
        line, self.buf = self.buf.split(b"\n", 1)
        return line.decode()

    def send(self, text: str, timeout: float) -> dict | None:
        """Have the probe send `text`; its report, or None if send() did not return in time."""
        self.proc.stdin.write(text.encode() + b"\n")
        self.proc.stdin.flush()
        assert self.line(10.0) == "sending", self.stderr()
        report = self.line(timeout)
        return json.loads(report) if report else None

    def stderr(self) -> str:
        if self.proc.poll() is None:
            return "(still running)"
        return self.proc.stderr.read().decode()[-2000:]

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()
        for f in (self.proc.stdin, self.proc.stdout, self.proc.stderr):
            f.close()


def _port(middleware: str) -> int:
    """Each middleware its own port: the tests share one network."""
    return BASE_PORT + messaging.MIDDLEWARES.index(middleware)


def _deliver(sender: Probe, receiver: Probe) -> list[dict]:
    """r1 sends until r3 printed a message; the reports of the sends it took."""
    reports = []
    deadline = time.monotonic() + DELIVERY_WAIT_S
    i = 0
    while time.monotonic() < deadline:
        i += 1
        report = sender.send(f"hello {i}", deadline - time.monotonic())
        assert report is not None, "a send did not return within the delivery wait"
        reports.append(report)
        got = receiver.line(1.0)
        if got is not None:
            assert got.startswith("hello "), got
            return reports
    raise AssertionError(f"nothing arrived at r3 in {DELIVERY_WAIT_S:g} s: {reports[-3:]}")


@pytest.mark.parametrize("middleware", MIDDLEWARES)
def test_a_message_from_r1_arrives_at_r3_two_hops_away(chain, middleware):
    port = _port(middleware) + 10  # apart from the dead-peer test's connections
    r3 = Probe(chain, 3, middleware, port, "listen")
    r1 = None
    try:
        r1 = Probe(chain, 1, middleware, port, "send", "3")
        reports = _deliver(r1, r3)
        assert reports[-1]["ok"] is True
        stats = reports[-1]["stats"]
        assert stats["sent"] >= 1 and stats["sent"] + stats["failed"] == len(reports)
    finally:
        for p in (r1, r3):
            if p is not None:
                p.kill()


@pytest.mark.parametrize("middleware", BOUNDED)
def test_with_r3_killed_each_send_of_r1_returns_within_the_send_timeout(chain, middleware):
    port = _port(middleware)
    r3 = Probe(chain, 3, middleware, port, "listen")
    r1 = None
    try:
        r1 = Probe(chain, 1, middleware, port, "send", "3")
        _deliver(r1, r3)
        r3.kill()
        time.sleep(0.5)  # r3's kernel closes its connections: r1 hears the FIN or RST
        bound = TIMEOUT_MS / 1000 + SLACK_S
        # nanomsg queues up to 8 messages for a teammate it has lost, Zenoh and DDS take
        # them until its lease ends (all counted as sent: docs/middleware.md); then every
        # send fails. Sending goes on until three in a row have failed.
        reports: list = []
        give_up = time.monotonic() + LEASE_S.get(middleware, 0.0) + 10.0
        while time.monotonic() < give_up and (
            len(reports) < 12 or any(rep["ok"] for rep in reports[-3:])
        ):
            reports.append(r1.send(f"after {len(reports)}", bound + 5.0))
            assert reports[-1] is not None, "a send did not return"
            if middleware in LEASE_S:
                time.sleep(0.05)
        took = [rep["s"] for rep in reports]
        assert max(took) <= bound, took
        assert [rep["ok"] for rep in reports[-3:]] == [False] * 3, reports[-3:]
        if middleware in WAITS_THE_TIMEOUT:
            assert all(rep["s"] >= TIMEOUT_MS / 1000 * 0.5 for rep in reports[-3:]), took
        else:  # no subscriber left: refused at once
            assert all(rep["s"] < TIMEOUT_MS / 1000 * 0.5 for rep in reports[-3:]), took
        stats = reports[-1]["stats"]
        assert stats["blocked_max_s"] <= bound and stats["sending"] == 0
    finally:
        for p in (r1, r3):
            if p is not None:
                p.kill()


@pytest.mark.parametrize("middleware", [_param("zeromq-reqrep")])
def test_with_r3_killed_a_zeromq_reqrep_send_of_r1_never_returns(chain, middleware):
    port = _port(middleware)
    r3 = Probe(chain, 3, middleware, port, "listen")
    r1 = None
    try:
        r1 = Probe(chain, 1, middleware, port, "send", "3")
        reports = _deliver(r1, r3)
        assert reports[-1]["ok"] is True  # the reply came: r3 took the message
        r3.kill()
        time.sleep(0.5)
        report = r1.send("after", BLOCK_WAIT_S)
        assert report is None, f"the send returned: {report}"
        assert r1.proc.poll() is None  # still inside send(), awaiting r3's reply
    finally:
        for p in (r1, r3):
            if p is not None:
                p.kill()


def _small_map(path: str) -> None:
    """A walled 4 x 4 m room (80 x 80 pixels of 5 cm): a team of two explores it quickly."""
    img = np.full((80, 80), 255, dtype=np.uint8)
    img[:2, :] = img[-2:, :] = img[:, :2] = img[:, -2:] = 0
    cv2.imwrite(path, img)


def test_a_team_run_over_zeromq_finishes_and_counts_its_messages(tmp_path):
    if messaging.unavailable("zeromq"):
        pytest.skip(messaging.unavailable("zeromq"))
    name = "mwc" + uuid.uuid4().hex[:5]
    room, out = str(tmp_path / "room.png"), str(tmp_path / "run")
    _small_map(room)
    argv = [
        os.path.join(PROJECT_ROOT, ".venv", "bin", "testbed"), "run", "--robots", "2",
        "--comm-range", "20", "--laser-range", "1.5", "--map", room, "--time-scale", "5",
        "--max-steps", "1500", "--middleware", "zeromq", "--capture", "--name", name,
        "--out", out, "--quiet",
    ]  # fmt: skip
    try:
        r = subprocess.run(argv, capture_output=True, text=True, timeout=300)
    finally:
        destroy(name)
    assert r.returncode == 0, r.stderr[-2000:]
    with open(os.path.join(out, "result.json")) as f:
        result = json.load(f)
    assert result["status"] == "complete", result["status_detail"]
    assert result["config"]["extra"]["middleware"] == "zeromq"
    msg = result["messaging"]
    assert msg["middleware"] == "zeromq" and msg["team"]["robots"] == 2
    team = msg["team"]
    assert team["sent"] > 0 and team["received"] > 0 and team["duplicates"] == 0
    for k in (1, 2):
        with open(os.path.join(out, "robots", f"r{k}.json")) as f:
            detail = json.load(f)
        assert detail["middleware"] == "zeromq"
        assert msg["robots"][f"r{k}"] == detail["messenger"] | detail["arrivals"]
        assert detail["messenger"]["blocked_max_s"] <= 0.010 + SLACK_S  # 50 ms / K=5
    # The captures see the same messages, in ZeroMQ's framing, and ZeroMQ's own bytes.
    wire = pcapmetrics.run_metrics(out).to_json()["middleware"]
    assert (wire["name"], wire["framing"]) == ("zeromq", "zmtp")
    assert team["received"] <= wire["messages"] <= team["sent"], (team, wire)
    assert wire["unparsed_bytes"] == 0 and wire["protocol_bytes"] >= 64 * 2
    assert 0 < wire["message_fraction_bytes"] < 1


# The captures' classes of the two middlewares not over the goal port's framings of TCP.
CAPTURED = [_param(m) for m in ("zenoh", "dds")]


def _tshark_submessages(pcap: str, addr: str) -> list[tuple[list[int], bytes]]:
    """What tshark's own RTPS dissector finds in the DDS datagrams `addr` transmitted: each
    one's submessage ids, and its UDP payload."""
    ports = " || ".join(f"udp.dstport == {p}" for p in pcapmetrics.DDS_PORTS)
    argv = ["tshark", "-n", "-r", pcap, "-Y", f"ip.src == {addr} && !icmp && ({ports})", "-T",
            "fields", "-E", "occurrence=a", "-e", "rtps.sm.id", "-e", "udp.payload"]  # fmt: skip
    out = subprocess.run(argv, capture_output=True, text=True, check=True).stdout
    rows = [line.split("\t") for line in out.splitlines()]
    return [([int(i, 16) for i in ids.split(",")], bytes.fromhex(p)) for ids, p in rows]


@pytest.mark.parametrize("middleware", CAPTURED)
def test_a_captured_team_run_counts_as_many_messages_as_the_robots_sent(tmp_path, middleware):
    """A 2-robot run within range (no loss): each robot's messages in its capture are those
    its messenger sent (`sent`: sends the middleware took), and all arrived (`received`)."""
    from testbed.analysis import rtps

    name = "mwp" + uuid.uuid4().hex[:5]
    out = str(tmp_path / "run")
    argv = [
        os.path.join(PROJECT_ROOT, ".venv", "bin", "testbed"), "run", "--robots", "2",
        "--comm-range", "20", "--time-scale", "5", "--max-steps", "300", "--middleware",
        middleware, "--capture", "--name", name, "--out", out, "--quiet",
    ]  # fmt: skip
    try:
        r = subprocess.run(argv, capture_output=True, text=True, timeout=300)
    finally:
        destroy(name)
    # 300 steps explore part of the map: the run ends at its step cap (exit status 1).
    assert r.returncode in (0, 1), r.stderr[-2000:]
    with open(os.path.join(out, "result.json")) as f:
        result = json.load(f)
    assert result["status"] in ("complete", "step_cap"), result["status_detail"]
    msg = result["messaging"]
    metrics = pcapmetrics.run_metrics(out).to_json()  # every key of routing.json
    wire = metrics["middleware"]
    assert (wire["name"], wire["framing"]) == (
        middleware,
        pcapmetrics.MIDDLEWARE_FRAMING[middleware],
    )
    assert msg["team"]["sent"] > 0 and msg["team"]["received"] == msg["team"]["sent"]
    for k, teammate in ((1, 2), (2, 1)):
        mine = metrics["robots"][f"r{k}"]["middleware"]
        assert mine["messages"] == msg["robots"][f"r{k}"]["sent"], (k, mine, msg)
        assert mine["messages"] == msg["robots"][f"r{teammate}"]["received"]
        assert mine["unparsed_bytes"] == 0 and 0 < mine["message_fraction_bytes"] < 1
    assert wire["messages"] == msg["team"]["sent"]
    kinds = wire["protocol_by_kind"]
    assert wire["protocol_bytes"] == sum(v["bytes"] for v in kinds.values())
    if middleware == "zenoh":
        assert kinds["handshake"]["count"] >= 4 and kinds["keep_alive"]["count"] > 0
        assert kinds["message_headers"]["count"] == wire["messages"]
        return
    assert wire["ports"] == [5111, 5112] and wire["tcp_control_packets"] == 0
    assert kinds["spdp"]["count"] > 0 and kinds["sedp"]["count"] > 0
    assert kinds["data_headers"]["count"] == wire["messages"]
    # The walk reads each datagram's submessages as tshark's RTPS dissector does.
    datagrams = 0
    for k in (1, 2):
        pcap = os.path.join(out, "pcaps", f"r{k}.pcap")
        for ids, payload in _tshark_submessages(pcap, robot_addr(k)):
            subs, walked = rtps.submessages(payload)
            assert [s[0] for s in subs] == ids and walked == len(payload)
            datagrams += 1
    assert datagrams == wire["tx_packets"] == kinds["rtps_header"]["count"]
