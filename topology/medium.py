"""The radio medium: one namespace of bridges and veth links that decides who hears whom.

Theory of operation (DESIGN.md, "The radio medium"). The medium namespace holds, per robot K,
a bridge `brK` with one ordinary port `rpK`, the veth peer of robot K's `wlan0`. A link between
robots i and j is one veth pair `lixj` <-> `ljxi`, `lixj` a port of `bri` and `ljxi` a port of
`brj`, both marked *isolated*. An isolated port forwards only to non-isolated ports, so a
frame that robot i sends enters `bri` at `rpi`, goes out through every link port of `bri`,
arrives at the far bridges and leaves only through their robot ports: a broadcast from i
reaches exactly the robots linked to i, once each, and never hops link to link.

Frames leaving through `lixj` travel from i to j, so a qdisc on `lixj` shapes exactly that
direction of that link (see topology.impair). Removing a link disables the bridge port of
its near end (see `set_links`): the robots' own `wlan0` stay up and notice nothing but
silence, as on a real radio.

Requests go out in batches through topology.rtnl (a raw rtnetlink socket of the medium
namespace, held by an NsWorker); robot-side configuration (sysctls, address) runs in one
thread that visits each robot's namespace in turn. pyroute2's IPRoute serves the rest (tc,
dumps), where speed does not matter.
"""

import logging
import os
import socket
import time

from topology import names, netns, rtnl
from topology.impair import Impairer
from topology.spec import Impairment

log = logging.getLogger(__name__)

# Set before wlan0 exists so that it inherits them from conf.default (DESIGN.md).
# accept_dad=0: the IPv6 link-local address (babeld speaks over it) is usable at once.
ROBOT_SYSCTLS = (
    ("net.ipv4.ip_forward", 1),
    ("net.ipv4.conf.all.send_redirects", 0),
    ("net.ipv4.conf.default.send_redirects", 0),
    ("net.ipv4.conf.all.accept_redirects", 0),
    ("net.ipv4.conf.default.accept_redirects", 0),
    ("net.ipv4.conf.all.rp_filter", 0),
    ("net.ipv4.conf.default.rp_filter", 0),
    ("net.ipv6.conf.default.accept_dad", 0),
)
WLAN_SYSCTLS = (
    "net.ipv4.conf.wlan0.send_redirects",
    "net.ipv4.conf.wlan0.accept_redirects",
    "net.ipv4.conf.wlan0.rp_filter",
)

# Interface indices are ours to choose (per namespace): no request ever looks a name up.
LO_INDEX = 1
WLAN_INDEX = 10


def bridge_index(k: int) -> int:
    return 1_000_000 + k


def port_index(k: int) -> int:
    return 2_000_000 + k


def end_index(i: int, j: int) -> int:
    return 10_000_000 + i * 1000 + j


_ENSLAVE = rtnl.LinkTemplate(master=0)
_ISOLATE = rtnl.LinkTemplate(isolated=True)
_UP = rtnl.LinkTemplate(up=True)
_PORT_ON = rtnl.LinkTemplate(rtnl.port_state, state=rtnl.BR_STATE_FORWARDING)
_PORT_OFF = rtnl.LinkTemplate(rtnl.port_state, state=rtnl.BR_STATE_DISABLED)


def _configure_robot(k: int) -> None:
    """Runs inside robot k's namespace: sysctls first, then address and state of wlan0, lo."""
    for key, value in ROBOT_SYSCTLS:
        netns.write_sysctl(key, value)
    for key in WLAN_SYSCTLS:  # inherited from conf.default already; made explicit for wlan0
        netns.write_sysctl(key, 0)
    batch = rtnl.Batch()
    batch.add(_UP(LO_INDEX), f"r{k}: lo up")
    # A /32 and no subnet route: every route belongs to the routing daemon.
    batch.add(rtnl.addr(WLAN_INDEX, names.robot_addr(k), 32), f"r{k}: address on wlan0")
    batch.add(_UP(WLAN_INDEX), f"r{k}: wlan0 up")
    with rtnl.open_socket() as sock:
        batch.send(sock)


class Medium:
    """The bridges and links of one testbed, inside its medium namespace."""

    def __init__(self, testbed: str, time_scale: float = 1.0):
        self.testbed = testbed
        self.ns = names.medium_ns(testbed)
        self.worker: netns.NsWorker | None = None
        self.impairer: Impairer | None = None
        self.time_scale = time_scale
        self.pairs: set[tuple[int, int]] = set()  # veth pairs that exist (on or off)
        self._pending: set[int] = set()  # new link ends the bridges may not forward through yet

    # -- life cycle -------------------------------------------------------------------------

    def open(self) -> None:
        """Start the worker in an existing medium namespace (creating nothing)."""
        self.worker = netns.NsWorker(self.ns)
        self.impairer = Impairer(self.ns, self.worker, self.time_scale)

    def setup(self) -> None:
        """First use of a fresh medium namespace: lo up, no IPv6 on bridges and links."""

        def work(ipr) -> None:
            netns.write_sysctl("net.ipv6.conf.default.disable_ipv6", 1)
            netns.write_sysctl("net.ipv6.conf.all.disable_ipv6", 1)

        self.worker.call(work)
        self._send([(rtnl.link(LO_INDEX, up=True), "medium: lo up")])

    def close(self) -> None:
        if self.impairer is not None:
            self.impairer.close()
        if self.worker is not None:
            self.worker.close()
            self.worker = None

    def _send(self, requests: list[tuple[bytes, str]]) -> None:
        batch = rtnl.Batch()
        for req, what in requests:
            batch.add(req, what)
        batch.send(self.worker.nl)

    # -- robots -----------------------------------------------------------------------------

    def add_robots(self, ks: list[int]) -> None:
        """Per robot K: bridge brK, and the veth rpK <-> wlan0, wlan0 made in K's namespace.
        The robots' own side is configure_robots()."""
        fds = {k: os.open(netns.path(names.robot_ns(self.testbed, k)), os.O_RDONLY) for k in ks}
        try:
            reqs = []
            for k in ks:
                br, port = bridge_index(k), port_index(k)
                reqs.append((rtnl.link(br, ifname=names.bridge(k), kind="bridge", up=True,
                                       create=True), f"create {names.bridge(k)}"))  # fmt: skip
                reqs.append((rtnl.link(port, ifname=names.robot_port(k), kind="veth", master=br,
                                       up=True, create=True,
                                       veth_peer=(names.ROBOT_IFACE, WLAN_INDEX, fds[k])),
                             f"create {names.robot_port(k)} and r{k}'s wlan0"))  # fmt: skip
            self._send(reqs)
        finally:
            for fd in fds.values():
                os.close(fd)

    def configure_robots(self, ks: list[int]) -> None:
        """Each robot's own side (sysctls, address, up), all robots in one thread."""
        robot_ns = [names.robot_ns(self.testbed, k) for k in ks]
        netns.run_in_each(robot_ns, lambda ns: _configure_robot(int(ns.rsplit("-r", 1)[1])))

    # -- links ------------------------------------------------------------------------------

    @staticmethod
    def _toggle_request(i: int, j: int, on: bool) -> tuple[bytes, str]:
        return (_PORT_ON if on else _PORT_OFF)(
            end_index(i, j)
        ), f"link {i}-{j} {'on' if on else 'off'}"

    def create_pairs(self, pairs: list[tuple[int, int]]) -> None:
        """Create the veth pairs of links met for the first time: both ends up, in their
        bridges and isolated. set_links() waits until the bridges forward through them."""
        new = [p for p in pairs if p not in self.pairs]
        reqs = []
        for i, j in new:
            a, b = end_index(i, j), end_index(j, i)
            what = f"link {i}-{j}"
            reqs += [
                (rtnl.link(a, ifname=names.link_end(i, j), kind="veth", master=bridge_index(i),
                           create=True, veth_peer=(names.link_end(j, i), b, None)),
                 f"create {what}"),
                (_ENSLAVE(b, bridge_index(j)), f"{what}: far end into {names.bridge(j)}"),
                (_ISOLATE(a), f"{what}: isolate near end"),
                (_ISOLATE(b), f"{what}: isolate far end"),
                (_UP(b), f"{what}: far end up"),
                (_UP(a), f"{what}: near end up"),
            ]  # fmt: skip
        self._send(reqs)
        self.pairs.update(new)
        self._pending |= {end_index(i, j) for i, j in new} | {end_index(j, i) for i, j in new}

    def _wait_forwarding(self, indices: set[int], timeout: float = 5.0) -> None:
        """The kernel brings a new veth's carrier up asynchronously (linkwatch), and only then
        does the bridge forward through it: wait for that, so a link is usable on return."""

        def forwarding(ipr) -> set[int]:
            ready = set()
            for port in ipr.get_links(family=socket.AF_BRIDGE):
                if port["index"] in indices:
                    info = port.get_attr("IFLA_PROTINFO")
                    if info is not None and info.get_attr("IFLA_BRPORT_STATE") == 3:
                        ready.add(port["index"])
            return ready

        deadline = time.monotonic() + timeout
        while True:
            pending = indices - self.worker.call(forwarding)
            if not pending:
                return
            if time.monotonic() > deadline:
                raise TimeoutError(f"{len(pending)} new link ends did not start forwarding")
            time.sleep(0.005)

    def set_links(self, add: list[tuple[int, int]], remove: list[tuple[int, int]]) -> None:
        """Switch the links in `add` on and those in `remove` off, in one batch. Pairs are
        (i, j) with i < j; `add` must name pairs that exist (create_pairs).

        A link is switched off by setting the bridge-port state of its near end to disabled:
        the bridge neither forwards frames out through it nor accepts frames coming in, so
        both directions stop, synchronously, in one request. Deleting the veth pair instead
        costs ~15 ms (the kernel waits for an RCU grace period), and taking an end down is
        asynchronous (carrier changes go through linkwatch); both would also drop the link's
        qdiscs and loss rules, to be rebuilt when the robots meet again."""
        missing = [p for p in add if p not in self.pairs]
        if missing:
            raise ValueError(f"links {missing} have no veth pair yet")
        if self._pending:
            self._wait_forwarding(self._pending)
            self._pending.clear()
        reqs = [self._toggle_request(i, j, False) for i, j in remove]
        reqs += [self._toggle_request(i, j, True) for i, j in add]
        self._send(reqs)

    def set_link_impairment(self, i: int, j: int, imp: Impairment) -> None:
        """Apply `imp` to both directions of link i-j."""
        self.impairer.apply(names.link_end(i, j), imp)
        self.impairer.apply(names.link_end(j, i), imp)

    def set_direction_impairment(self, i: int, j: int, imp: Impairment) -> None:
        """Apply `imp` to frames going from i to j only."""
        self.impairer.apply(names.link_end(i, j), imp)

    def kernel_links(self) -> set[tuple[int, int]]:
        """The links as the kernel has them: pairs (i, j), i < j, whose near end forwards.
        Also records which veth pairs exist, for a process that attaches to the testbed."""

        def work(ipr) -> tuple[set, set]:
            pairs, up = set(), set()
            for port in ipr.get_links(family=socket.AF_BRIDGE):
                parsed = names.parse_link_end(port.get_attr("IFLA_IFNAME"))
                if parsed and parsed[0] < parsed[1]:
                    pairs.add(parsed)
                    info = port.get_attr("IFLA_PROTINFO")
                    if info is not None and info.get_attr("IFLA_BRPORT_STATE") == 3:
                        up.add(parsed)
            return pairs, up

        pairs, up = self.worker.call(work)
        self.pairs |= pairs
        return up
