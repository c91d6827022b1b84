"""The radio medium: one namespace of bridges and veth links that decides who hears whom.

Theory of operation (docs/architecture.md, "The radio medium"). The medium namespace holds,
per robot K, a bridge `brK` with one ordinary port `rpK`, the veth peer of robot K's `wlan0`.
A link between robots i and j is one veth pair `lixj` <-> `ljxi`, `lixj` a port of `bri` and
`ljxi` a port of `brj`, both marked *isolated*. An isolated port forwards only to non-isolated
ports, so a frame that robot i sends enters `bri` at `rpi`, goes out through every link port
of `bri`, arrives at the far bridges and leaves only through their robot ports: a broadcast
from i reaches exactly the robots linked to i, once each, and never hops link to link.

Frames leaving through `lixj` travel from i to j, so a qdisc on `lixj` shapes exactly that
direction of that link (see topology.kernel.impair). Removing a link disables the bridge port of
its near end (see `set_links`): the robots' own `wlan0` stay up and notice nothing but
silence, as on a real radio.

Requests go out in batches through topology.kernel.rtnl (a raw rtnetlink socket of the medium
namespace, held by an NsWorker); robot-side configuration (sysctls, address) runs in one
thread that visits each robot's namespace in turn. pyroute2's IPRoute serves the rest (tc,
dumps), where speed does not matter.

The robots' network timers follow the time scale (topology.kernel.nettimers): the first robot's
namespace is probed for the timer sysctls it has and for the kernel's jiffy, the plan's values
are written there (a value the kernel refuses is recorded, not fatal) and then in every other
robot's namespace. `VethMedium.timers` is the record, whichever routing daemon installs the routes.
"""

import errno
import logging
import os
import time

from topology import names
from topology.kernel import netns, nettimers, rtnl
from topology.kernel.impair import Impairer
from topology.spec import Impairment

log = logging.getLogger(__name__)

# Set before wlan0 exists so that it inherits them from conf.default (docs/architecture.md,
# "Kernel facts that shaped this").
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
# wlan0 exists by then (add_robot_ports makes it before configure_robots runs), so it did
# not inherit the defaults above: its own keys too, before it goes up (accept_dad=0 then
# keeps its link-local address from being "tentative" for a second).
WLAN_SYSCTLS = (
    "net.ipv4.conf.wlan0.send_redirects",
    "net.ipv4.conf.wlan0.accept_redirects",
    "net.ipv4.conf.wlan0.rp_filter",
    "net.ipv6.conf.wlan0.accept_dad",
)

# Interface indices are ours to choose (per namespace): no request ever looks a name up.
LO_INDEX = 1
WLAN_INDEX = 10
ASK_PORTS_UP_TO = 512  # new link ends checked one by one below this, by one dump above


def bridge_index(k: int) -> int:
    return 1_000_000 + k


def port_index(k: int) -> int:
    return 2_000_000 + k


def end_index(i: int, j: int) -> int:
    return 10_000_000 + i * 1000 + j


_ENSLAVE = rtnl.Template(rtnl.link, ints=("index", "master"))
_ISOLATE_UP = rtnl.Template(rtnl.link, isolated=True, up=True)
_UP = rtnl.Template(rtnl.link, up=True)
_PORT_ON = rtnl.Template(rtnl.port_state, state=rtnl.BR_STATE_FORWARDING)
_PORT_OFF = rtnl.Template(rtnl.port_state, state=rtnl.BR_STATE_DISABLED)
_VETH: dict[tuple[int, int], rtnl.Template] = {}
_BRIDGE: dict[int, rtnl.Template] = {}
_ROBOT_VETH: dict[int, rtnl.Template] = {}


def _bridge(k: int) -> bytes:
    name = names.bridge(k)
    if len(name) not in _BRIDGE:
        _BRIDGE[len(name)] = rtnl.Template(rtnl.bridge, strs={"ifname": len(name)})
    return _BRIDGE[len(name)](index=bridge_index(k), ifname=name)


def _robot_veth(k: int, nsfd: int) -> bytes:
    """rpK in bridge K, up, with its peer wlan0 created in robot K's namespace."""
    name = names.robot_port(k)
    if len(name) not in _ROBOT_VETH:
        _ROBOT_VETH[len(name)] = rtnl.Template(
            rtnl.veth, ints=("index", "master", "peer_nsfd"), strs={"ifname": len(name)},
            peer_name=names.ROBOT_IFACE, peer_index=WLAN_INDEX, up=True,
        )  # fmt: skip
    return _ROBOT_VETH[len(name)](index=port_index(k), ifname=name, master=bridge_index(k),
                                  peer_nsfd=nsfd)  # fmt: skip


def _veth(index: int, ifname: str, master: int, peer_name: str, peer_index: int) -> bytes:
    """A veth-creation request, from a template per pair of name lengths."""
    key = (len(ifname), len(peer_name))
    if key not in _VETH:
        _VETH[key] = rtnl.Template(rtnl.veth, ints=("index", "master", "peer_index"),
                                   strs={"ifname": key[0], "peer_name": key[1]})  # fmt: skip
    return _VETH[key](index=index, ifname=ifname, master=master, peer_name=peer_name,
                      peer_index=peer_index)  # fmt: skip


def read_sysctl(key: str) -> int | None:
    """A sysctl of the calling thread's namespace as an integer; None if it has no such key.
    (/proc/sys/net is the calling thread's namespace's, unlike /proc/net.)"""
    try:
        with open("/proc/sys/" + key.replace(".", "/")) as f:
            return int(f.read().split()[0])
    except FileNotFoundError:
        return None


def jiffy_us() -> int:
    """The kernel's jiffy in microseconds, as the kernel rounds a millisecond sysctl kept in
    jiffies: lo's ARP retransmit time (lo does no ARP) set to 1 ms reads back as one jiffy,
    then is put back. Exact at HZ 100, 250 and 1000."""
    key = "net.ipv4.neigh.lo.retrans_time_ms"
    before = read_sysctl(key)
    try:
        netns.write_sysctl(key, 1)
        return 1000 * (read_sysctl(key) or 1)
    finally:
        if before is not None:
            netns.write_sysctl(key, before)


def plan_timers(time_scale: float) -> nettimers.NetworkTimers:
    """Runs inside a fresh robot namespace: the timer sysctls it has, read, and the plan for
    this time scale; its values are written here, those the kernel refuses recorded as such."""
    dev = names.ROBOT_IFACE
    defaults = {}
    for knob in nettimers.KNOBS:
        value = read_sysctl(knob.sysctl(dev))
        if value is not None:
            defaults[knob.sysctl(dev)] = value
    timers = nettimers.plan(time_scale, defaults, jiffy_us(), os.uname().release, dev)
    for key, value in timers.writes():
        try:
            netns.write_sysctl(key, value)
        except OSError as e:
            if e.errno not in (errno.EINVAL, errno.ERANGE):
                raise
            timers = nettimers.refused(timers, key, os.strerror(e.errno))
    return timers


def _configure_robot(k: int, timer_writes: list[tuple[str, int]] | None = None) -> None:
    """Runs inside robot k's namespace: sysctls first, then address and state of wlan0, lo."""
    for key, value in ROBOT_SYSCTLS:
        netns.write_sysctl(key, value)
    for key in WLAN_SYSCTLS:
        netns.write_sysctl(key, 0)
    for key, value in timer_writes or ():
        netns.write_sysctl(key, value)
    batch = rtnl.Batch()
    batch.add(_UP(index=LO_INDEX), f"r{k}: lo up")
    # A /32 and no subnet route: every route belongs to the routing daemon.
    batch.add(rtnl.addr(WLAN_INDEX, names.robot_addr(k), 32), f"r{k}: address on wlan0")
    batch.add(_UP(index=WLAN_INDEX), f"r{k}: wlan0 up")
    with rtnl.open_socket() as sock:
        batch.send(sock)


class VethMedium:
    """The bridges and links of one testbed, inside its medium namespace."""

    def __init__(self, testbed: str, time_scale: float = 1.0):
        self.testbed = testbed
        self.ns = names.medium_ns(testbed)
        self.worker: netns.NsWorker | None = None
        self.impairer: Impairer | None = None
        self.time_scale = time_scale
        self.pairs: set[tuple[int, int]] = set()  # veth pairs that exist (on or off)
        self.timers: nettimers.NetworkTimers | None = None  # set by configure_robots
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

        assert self.worker is not None  # open() came first
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
        assert self.worker is not None  # open() came first
        batch.send(self.worker.nl)

    # -- robots -----------------------------------------------------------------------------

    def add_bridges(self, ks: list[int]) -> None:
        """Bridge brK per robot K."""
        self._send([(_bridge(k), f"create {names.bridge(k)}") for k in ks])

    def add_robot_ports(self, ks: list[int]) -> None:
        """Per robot K: the veth rpK <-> wlan0, rpK in bridge K and wlan0 made in K's
        namespace. The robots' own side is configure_robots()."""
        fds = {k: os.open(netns.path(names.robot_ns(self.testbed, k)), os.O_RDONLY) for k in ks}
        try:
            self._send([
                (_robot_veth(k, fds[k]), f"create {names.robot_port(k)} and r{k}'s wlan0")
                for k in ks
            ])  # fmt: skip
        finally:
            for fd in fds.values():
                os.close(fd)
        # Carrier comes when the robot's wlan0 goes up (configure_robots); set_links waits.
        self._pending |= {port_index(k) for k in ks}

    def configure_robots(self, ks: list[int]) -> None:
        """Each robot's own side (sysctls, network timers, address, up), all robots in one
        thread; the timers are planned in the first robot's namespace (`self.timers`)."""
        robot_ns = [names.robot_ns(self.testbed, k) for k in ks]
        if not robot_ns:
            return
        self.timers = netns.run_in(robot_ns[0], lambda: plan_timers(self.time_scale))
        writes = self.timers.writes()
        netns.run_in_each(robot_ns, lambda ns: _configure_robot(int(ns.rsplit("-r", 1)[1]), writes))

    # -- links ------------------------------------------------------------------------------

    @staticmethod
    def _toggle_request(i: int, j: int, on: bool) -> tuple[bytes, str]:
        request = (_PORT_ON if on else _PORT_OFF)(index=end_index(i, j))
        return request, f"link {i}-{j} {'on' if on else 'off'}"

    def create_pairs(self, pairs: list[tuple[int, int]]) -> None:
        """Create the veth pairs of links met for the first time: both ends up, in their
        bridges and isolated. set_links() waits until the bridges forward through them."""
        if not pairs:
            return
        new = [p for p in pairs if p not in self.pairs]
        reqs = []
        for i, j in new:
            a, b = end_index(i, j), end_index(j, i)
            what = f"link {i}-{j}"
            # Four requests, each end isolated before it goes up: the link carries no frame
            # before both ends are isolated (the carrier comes with the far end's up). The
            # bridge applies slave data before flags, so isolating and raising share one
            # request; only the far end's enslaving must come before its own.
            reqs += [
                (_veth(a, names.link_end(i, j), bridge_index(i), names.link_end(j, i), b),
                 f"create {what}"),
                (_ISOLATE_UP(index=a), f"{what}: isolate near end, up"),
                (_ENSLAVE(index=b, master=bridge_index(j)),
                 f"{what}: far end into {names.bridge(j)}"),
                (_ISOLATE_UP(index=b), f"{what}: isolate far end, up"),
            ]  # fmt: skip
        self._send(reqs)
        self.pairs.update(new)
        self._pending |= {end_index(i, j) for i, j in new} | {end_index(j, i) for i, j in new}

    def _wait_forwarding(self, indices: set[int], timeout: float = 5.0) -> None:
        """The kernel brings a new veth's carrier up asynchronously (linkwatch), and only then
        does the bridge forward through it: wait for that (the port forwarding, its operstate
        up), so a link is usable on return. Usually nothing is left to wait for by the time
        this is called; the check is one dump, parsed by topology.kernel.rtnl in a few ms, or for a
        few ends (a feed's new links) a request per end."""
        deadline = time.monotonic() + timeout
        assert self.worker is not None  # open() came first
        while True:
            if len(indices) <= ASK_PORTS_UP_TO:  # a few: ask for them, not the thousands
                ports = rtnl.port_states(self.worker.nl, indices)
            else:
                ports = rtnl.bridge_ports(self.worker.nl)
            pending = {
                i for i in indices
                if ports.get(i, ("", -1, -1))[1:] != (rtnl.BR_STATE_FORWARDING, rtnl.IF_OPER_UP)
            }  # fmt: skip
            if not pending:
                return
            if time.monotonic() > deadline:
                raise TimeoutError(f"{len(pending)} new link ends did not start forwarding")
            indices = pending
            time.sleep(0.01)  # a dump is not free: leave the CPU to the kernel meanwhile

    def set_links(self, add: list[tuple[int, int]], remove: list[tuple[int, int]]) -> None:
        """Switch the links in `add` on and those in `remove` off, in one batch. Pairs are
        (i, j) with i < j; `add` must name pairs that exist (create_pairs).

        A link is switched off by setting the bridge-port state of its near end to disabled:
        the bridge neither forwards frames out through it nor accepts frames coming in, so
        both directions stop, synchronously, in one request. Deleting the veth pair instead
        costs ~15 ms (the kernel waits for an RCU grace period), and taking an end down is
        asynchronous (carrier changes go through linkwatch); both would also drop the link's
        qdiscs and loss rules, to be rebuilt when the robots meet again."""
        if not (add or remove or self._pending):
            return  # most world steps: nothing to switch, nothing to wait for
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
        assert self.impairer is not None  # open() came first
        self.impairer.apply(names.link_end(i, j), imp)
        self.impairer.apply(names.link_end(j, i), imp)

    def kernel_links(self) -> set[tuple[int, int]]:
        """The links as the kernel has them: pairs (i, j), i < j, whose near end forwards.
        Also records which veth pairs exist, for a process that attaches to the testbed."""
        pairs, up = set(), set()
        assert self.worker is not None  # open() came first
        for name, port_state, _ in rtnl.bridge_ports(self.worker.nl).values():
            parsed = names.parse_link_end(name)
            if parsed and parsed[0] < parsed[1]:
                pairs.add(parsed)
                if port_state == rtnl.BR_STATE_FORWARDING:
                    up.add(parsed)
        self.pairs |= pairs
        return up
