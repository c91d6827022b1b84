"""The ns3-wifi radio medium: an 802.11 channel simulated by ns-3, carrying the robots' frames.

Theory of operation (docs/ns3-medium.md). Where the veth medium (topology.radio.veth) joins the
robots by links switched on and off, this medium has one shared channel: the program
build/tb-ns3-wifi (native/ns3wifi/wifi-medium.cc), one process per testbed, running ns-3's
real-time simulator in the medium namespace. Robot K's `wlan0` is, as with veth, one end of a
veth pair whose other end `rpK` lies in the medium namespace; here `rpK` is in no bridge: the
ns-3 process reads and writes it through an AF_PACKET socket and relays the frames to and from
robot K's ghost WiFi device (802.11 ad hoc on one YansWifiChannel). So frames contend for
airtime, collide and are retried by a real DCF; who hears whom is the channel's propagation
at the robots' positions: a cut-off at the communication range by default (the veth disc).

`wlan0` gets the MAC of its robot's WiFi device (`robot_mac`), so no frame is rewritten; its
transmit checksum offload is off, since the frames leave the kernel through AF_PACKET with
their checksums still to be filled in otherwise (and with it goes segmentation offload).

The controller (topology.network.Network) keeps computing the range model's link set for the
view and the oracle; the positions go to the ns-3 process every step (`set_positions`, one
line over its Unix socket, answered once the simulator has applied it). `kernel_links` asks
the channel which pairs hear each other, so a process that attaches to a `net up` testbed
sees the truth. The process is recorded in the testbed's state (role "ns3-wifi") and stopped
by its pid with the others (topology.teardown.destroy).

Each frame the channel delivers to a robot leaves one record of its relay lag (what the
relay added to its trip beyond the channel's emulated time) in the testbed's run directory,
`relay-lag.bin` (docs/ns3-medium.md, "Each frame's relay lag"); `keep_lag_file` copies it
out at the end of a run, and testbed.analysis.relaylag reads it.

Not supported here (yet): link impairments (no link to put them on), the los range models.
"""

import json
import logging
import os
import shutil
import socket
import struct
import subprocess
import time

from common import envswitch
from common.errors import TestbedError, UsageError
from common.paths import PROJECT_ROOT
from topology import names, state
from topology.kernel import netns, processes, rtnl
from topology.names import LAG_FILE
from topology.radio.veth import WLAN_INDEX, VethMedium, port_index
from topology.spec import Impairment, NetworkSpec, Position

log = logging.getLogger(__name__)

ROLE = "ns3-wifi"
NS3_HEADER = "/usr/include/ns3/wifi-module.h"  # installed with Debian's libns3-dev
BINARY_ENV = "TESTBED_NS3_WIFI"  # another build of tb-ns3-wifi (tests, development)
START_TIMEOUT_S = 20.0
# SCHED_RR priority of the ns-3 process: the robots' motion-control threads have 1 and the
# world's step loop 2 (docs/architecture.md); the channel, part of the world, gets 2 too.
# TESTBED_REALTIME=0 turns it off, as everywhere.
RT_PRIORITY = 2
REQUEST_TIMEOUT_S = 10.0
SIOCETHTOOL = 0x8946
ETHTOOL_STXCSUM = 0x17
# The lag file's size cap (40 bytes a frame delivered: about 840 000 frames); the records
# past it are counted in the counters' lag_file.not_written.
LAG_CAP_BYTES = 32 << 20

Pair = tuple[int, int]


def binary() -> str:
    """The tb-ns3-wifi program (built by `make setup`)."""
    return os.environ.get(BINARY_ENV) or os.path.join(PROJECT_ROOT, "build", "tb-ns3-wifi")


def unbuilt_reason() -> str | None:
    """Why the medium is not here, in one line, or None where it is (or should be).

    `make setup` leaves the medium out where it cannot build it and writes its one line into
    build/tb-ns3-wifi.unbuilt; without libns3-dev there is nothing to build. Where ns-3 is
    installed and no such line was written, a missing program is a defect, not a reason."""
    if os.access(binary(), os.X_OK):
        return None
    try:
        with open(os.path.join(PROJECT_ROOT, "build", "tb-ns3-wifi.unbuilt")) as f:
            line = f.readline(500).strip()
    except OSError:
        line = ""
    if line:
        return line
    if not os.path.exists(NS3_HEADER):
        return "ns-3 is not installed (Debian's libns3-dev)"
    return None


def robot_mac(k: int) -> str:
    """Robot K's MAC, on wlan0 and on its WiFi device: locally administered, 10.0.0.K-like."""
    if not 1 <= k <= 0xFFFF:
        raise ValueError(f"no MAC for robot {k}")
    return f"02:00:0a:00:{k >> 8:02x}:{k & 0xFF:02x}"


def socket_path(testbed: str) -> str:
    return os.path.join(state.run_dir(testbed), "ns3-wifi.sock")


def lag_path(testbed: str) -> str:
    return os.path.join(state.run_dir(testbed), LAG_FILE)


def argv(
    spec: NetworkSpec, positions: list[Position], sock: str, lag_file: str | None = None
) -> list[str]:
    """The command line of the ns-3 process for this testbed (with `lag_file`, where its
    per-frame relay lag records go)."""
    out = [
        binary(), "--socket", sock, "--range", repr(spec.comm_range),
        "--loss", spec.wifi_loss, "--standard", spec.wifi_standard,
        "--time-scale", repr(spec.time_scale),
    ]  # fmt: skip
    if lag_file:
        out += ["--lag-file", lag_file, "--lag-cap-bytes", str(LAG_CAP_BYTES)]
    if spec.wifi_rate:
        out += ["--rate", spec.wifi_rate]
    if envswitch.value("TESTBED_REALTIME") == "1":
        out += ["--rt-priority", str(RT_PRIORITY)]
    for k, (x, y) in zip(spec.robot_ids(), positions, strict=True):
        out += ["--robot", f"{names.robot_port(k)},{robot_mac(k)},{x!r},{y!r}"]
    return out


def positions_request(positions: list[Position]) -> str:
    return "pos " + " ".join(f"{x!r} {y!r}" for x, y in positions)


def parse_links(answer: str) -> set[Pair]:
    """'links 1-2 2-3' -> {(1, 2), (2, 3)}."""
    words = answer.split()
    if not words or words[0] != "links":
        raise ValueError(f"not a links answer: {answer!r}")
    pairs = set()
    for word in words[1:]:
        i, j = (int(n) for n in word.split("-"))
        pairs.add((min(i, j), max(i, j)))
    return pairs


def _set_mac(mac: str) -> bytes:
    """RTM_NEWLINK setting wlan0's hardware address."""
    from pyroute2.netlink.rtnl.ifinfmsg import ifinfmsg

    m = ifinfmsg()
    m["index"] = WLAN_INDEX
    m["attrs"] = [("IFLA_ADDRESS", mac)]
    m["header"]["type"] = rtnl.RTM_NEWLINK
    m["header"]["flags"] = rtnl.REQUEST
    m.encode()
    return bytes(m.data)


def _tx_checksum_off(ifname: str) -> None:
    """`ethtool -K IFNAME tx off` in the calling thread's namespace (SIOCETHTOOL)."""
    import ctypes
    import fcntl

    value = ctypes.create_string_buffer(struct.pack("=II", ETHTOOL_STXCSUM, 0), 8)
    ifreq = struct.pack("16sP", ifname.encode(), ctypes.addressof(value)).ljust(40, b"\0")
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        fcntl.ioctl(sock, SIOCETHTOOL, ifreq)


def _prepare_wlan(k: int) -> None:
    """Runs in robot k's namespace before wlan0 goes up: its MAC and offloads."""
    batch = rtnl.Batch()
    batch.add(_set_mac(robot_mac(k)), f"r{k}: MAC of wlan0")
    with rtnl.open_socket() as sock:
        batch.send(sock)
    _tx_checksum_off(names.ROBOT_IFACE)


class Ns3Medium(VethMedium):
    """The ns3-wifi medium of one testbed: the veth ends in the medium namespace and the
    ns-3 process that carries frames between them. Offers what Network uses of VethMedium; the
    bridge and link methods have nothing to do here."""

    def __init__(self, spec: NetworkSpec):
        super().__init__(spec.name, spec.time_scale)
        self.spec = spec
        self.sock_path = socket_path(spec.name)
        self._conn: socket.socket | None = None
        self._buf = b""

    # -- bring-up ---------------------------------------------------------------------------

    def add_bridges(self, ks: list[int]) -> None:
        """No bridges on a shared channel."""

    def add_robot_ports(self, ks: list[int]) -> None:
        """Per robot K: the veth rpK <-> wlan0, rpK up in the medium, wlan0 in K's namespace."""
        fds = {k: os.open(netns.path(names.robot_ns(self.testbed, k)), os.O_RDONLY) for k in ks}
        try:
            self._send([
                (rtnl.link(port_index(k), ifname=names.robot_port(k), kind="veth", up=True,
                           create=True, veth_peer=(names.ROBOT_IFACE, WLAN_INDEX, fds[k])),
                 f"create {names.robot_port(k)} and r{k}'s wlan0")
                for k in ks
            ])  # fmt: skip
        finally:
            for fd in fds.values():
                os.close(fd)

    def configure_robots(self, ks: list[int]) -> None:
        robot_ns = [names.robot_ns(self.testbed, k) for k in ks]
        netns.run_in_each(robot_ns, lambda ns: _prepare_wlan(int(ns.rsplit("-r", 1)[1])))
        super().configure_robots(ks)

    def start(self, positions: list[Position]) -> subprocess.Popen:
        """Start the ns-3 process in the medium namespace; return once it answers. The caller
        records it (its pid) with the testbed."""
        exe = binary()
        if not os.access(exe, os.X_OK):
            why = unbuilt_reason() or "run `sudo make setup` (it needs Debian's libns3-dev)"
            raise UsageError(f"the ns3-wifi medium is not built ({exe}): {why}")
        os.makedirs(os.path.dirname(self.sock_path), exist_ok=True)
        logp = os.path.join(state.run_dir(self.testbed), "ns3-wifi.log")
        with open(logp, "w") as logf:
            proc = processes.spawn(
                self.ns, argv(self.spec, positions, self.sock_path, lag_path(self.testbed)),
                stdout=logf, stderr=subprocess.STDOUT,
            )  # fmt: skip
        deadline = time.monotonic() + START_TIMEOUT_S
        while True:
            if proc.poll() is not None:
                with open(logp) as f:
                    last = (f.read().strip().splitlines() or ["(no output)"])[-1]
                raise TestbedError(f"the ns-3 medium exited: {last}")
            try:
                if self.request("ping") == "ok":
                    return proc
            except OSError:
                self._disconnect()
            if time.monotonic() > deadline:
                proc.kill()
                raise TestbedError("the ns-3 medium did not start in time")
            time.sleep(0.02)

    # -- the channel ------------------------------------------------------------------------

    def set_positions(self, positions: list[Position]) -> None:
        """Move the ghost nodes; returns once the simulator has applied it."""
        answer = self._ask(positions_request(positions))
        if answer != "ok":
            raise TestbedError(f"ns-3 medium: {answer}")

    def kernel_links(self) -> set[Pair]:
        """The pairs that hear each other on the channel now."""
        return parse_links(self._ask("links"))

    def counters(self) -> dict:
        """The channel's counters: per robot (in robot order) frames relayed, MAC retries and
        drops, PHY drops by reason, airtime; how late the simulator ran (lateness) and
        handled the frames it relayed (relay_lag). docs/ns3-medium.md lists them."""
        return json.loads(self._ask("stats"))

    def keep_lag_file(self, dest: str) -> None:
        """Copy the per-frame relay lag records written so far (the process flushes them
        first) to `dest`. A copy that fails is logged: the run's delays then stay
        uncorrected, and its report says so."""
        answer = self._ask("flush")
        if answer != "ok":
            raise TestbedError(f"ns-3 medium: {answer}")
        try:
            shutil.copyfile(lag_path(self.testbed), dest)
        except OSError as e:
            log.warning("relay-lag records not kept: %s", e)

    def _ask(self, line: str) -> str:
        """request(), with a dead or stuck process reported as one TestbedError line."""
        try:
            return self.request(line)
        except OSError as exc:
            self._disconnect()
            logp = os.path.join(state.run_dir(self.testbed), "ns3-wifi.log")
            try:
                with open(logp) as f:
                    last = (f.read().strip().splitlines() or [""])[-1]
            except OSError:
                last = ""
            raise TestbedError(f"the ns-3 medium does not answer ({exc}) {last}".strip()) from None

    def create_pairs(self, pairs: list[Pair]) -> None:
        """No links to create: the channel decides who hears whom."""

    def set_links(self, add: list[Pair], remove: list[Pair]) -> None:
        """Nothing to switch: set_positions moved the robots on the channel."""

    def set_link_impairment(self, i: int, j: int, imp: Impairment) -> None:
        if not imp.is_none:
            raise UsageError("the ns3-wifi medium has no link impairments (yet)")

    # -- the control socket -----------------------------------------------------------------

    def request(self, line: str) -> str:
        """Send one request line, return the answer line."""
        if self._conn is None:
            conn = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            conn.settimeout(REQUEST_TIMEOUT_S)
            try:
                conn.connect(self.sock_path)
            except OSError:
                conn.close()
                raise
            self._conn, self._buf = conn, b""
        self._conn.sendall(line.encode() + b"\n")
        while b"\n" not in self._buf:
            chunk = self._conn.recv(1 << 16)
            if not chunk:
                self._disconnect()
                raise ConnectionError("the ns-3 medium closed its socket")
            self._buf += chunk
        answer, _, self._buf = self._buf.partition(b"\n")
        return answer.decode()

    def _disconnect(self) -> None:
        if self._conn is not None:
            self._conn.close()
            self._conn = None

    def close(self) -> None:
        self._disconnect()
        super().close()


def medium_for(spec: NetworkSpec) -> VethMedium:
    """The medium `spec` asks for (not yet opened)."""
    if spec.medium == "ns3-wifi":
        return Ns3Medium(spec)
    return VethMedium(spec.name, spec.time_scale)
