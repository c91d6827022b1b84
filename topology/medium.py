"""The radio medium: one namespace of bridges and veth links that decides who hears whom.

Theory of operation (DESIGN.md, "The radio medium"). The medium namespace holds, per robot K,
a bridge `brK` with one ordinary port `rpK`, the veth peer of robot K's `wlan0`. A link between
robots i and j is one veth pair `lixj` <-> `ljxi`, `lixj` a port of `bri` and `ljxi` a port of
`brj`, both marked *isolated*. An isolated port forwards only to non-isolated ports, so a
frame that robot i sends enters `bri` at `rpi`, goes out through every link port of `bri`,
arrives at the far bridges and leaves only through their robot ports: a broadcast from i
reaches exactly the robots linked to i, once each, and never hops link to link.

Frames leaving through `lixj` travel from i to j, so a qdisc on `lixj` shapes exactly that
direction of that link (see topology.impair). Removing a link deletes its veth pair: the
robots' own `wlan0` stay up and notice nothing but silence, as on a real radio.

All netlink work runs in one NsWorker parked in the medium namespace; robot-side
configuration (address, sysctls) runs in a short-lived thread inside the robot's namespace.
"""

import errno
import logging

from pyroute2.netlink.exceptions import NetlinkError

from topology import names, netns
from topology.impair import Impairer
from topology.spec import Impairment

log = logging.getLogger(__name__)

# Set before wlan0 exists so that it inherits them from conf.default (DESIGN.md).
ROBOT_SYSCTLS = (
    ("net.ipv4.ip_forward", 1),
    ("net.ipv4.conf.all.send_redirects", 0),
    ("net.ipv4.conf.default.send_redirects", 0),
    ("net.ipv4.conf.all.accept_redirects", 0),
    ("net.ipv4.conf.default.accept_redirects", 0),
    ("net.ipv4.conf.all.rp_filter", 0),
    ("net.ipv4.conf.default.rp_filter", 0),
)
WLAN_SYSCTLS = (
    "net.ipv4.conf.wlan0.send_redirects",
    "net.ipv4.conf.wlan0.accept_redirects",
    "net.ipv4.conf.wlan0.rp_filter",
)


def _index(ipr, ifname: str) -> int:
    found = ipr.link_lookup(ifname=ifname)
    if not found:
        raise LookupError(f"no interface {ifname}")
    return found[0]


def _configure_robot(k: int) -> None:
    """Runs inside robot k's namespace: sysctls first, then the robot's own wlan0 and lo."""
    from pyroute2 import IPRoute

    for key, value in ROBOT_SYSCTLS:
        netns.write_sysctl(key, value)
    with IPRoute() as ipr:
        lo = _index(ipr, "lo")
        ipr.link("set", index=lo, state="up")
        wlan = _index(ipr, names.ROBOT_IFACE)
        for key in WLAN_SYSCTLS:  # inherited from default already; made explicit for wlan0
            netns.write_sysctl(key, 0)
        # A /32 and no subnet route: every route belongs to the routing daemon.
        ipr.addr("add", index=wlan, address=names.robot_addr(k), prefixlen=32)
        ipr.link("set", index=wlan, state="up")


class Medium:
    """The bridges and links of one testbed, inside its medium namespace."""

    def __init__(self, testbed: str, time_scale: float = 1.0):
        self.testbed = testbed
        self.ns = names.medium_ns(testbed)
        self.worker: netns.NsWorker | None = None
        self.impairer: Impairer | None = None
        self.time_scale = time_scale

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
            ipr.link("set", index=_index(ipr, "lo"), state="up")

        self.worker.call(work)

    def close(self) -> None:
        if self.impairer is not None:
            self.impairer.close()
        if self.worker is not None:
            self.worker.close()
            self.worker = None

    # -- robots -----------------------------------------------------------------------------

    def add_robot(self, k: int) -> None:
        """Bridge brK, and the veth rpK <-> wlan0 with wlan0 created in robot k's namespace."""
        robot_ns_path = netns.path(names.robot_ns(self.testbed, k))

        def work(ipr) -> None:
            ipr.link("add", ifname=names.bridge(k), kind="bridge", br_stp_state=0)
            br = _index(ipr, names.bridge(k))
            ipr.link("set", index=br, state="up")
            ipr.link(
                "add",
                ifname=names.robot_port(k),
                kind="veth",
                peer={"ifname": names.ROBOT_IFACE, "net_ns_fd": robot_ns_path},
            )
            port = _index(ipr, names.robot_port(k))
            ipr.link("set", index=port, master=br, state="up")

        self.worker.call(work)
        netns.run_in(names.robot_ns(self.testbed, k), lambda: _configure_robot(k))

    # -- links ------------------------------------------------------------------------------

    def add_link(self, i: int, j: int) -> None:
        a, b = names.link_end(i, j), names.link_end(j, i)

        def work(ipr) -> None:
            ipr.link("add", ifname=a, kind="veth", peer=b)
            for end, k in ((a, i), (b, j)):
                idx = _index(ipr, end)
                ipr.link("set", index=idx, master=_index(ipr, names.bridge(k)))
                ipr.brport("set", index=idx, isolated=1)
                ipr.link("set", index=idx, state="up")

        self.worker.call(work)

    def remove_link(self, i: int, j: int) -> None:
        """Delete the veth pair of link i-j (deleting one end deletes both)."""
        end = names.link_end(i, j)

        def work(ipr) -> None:
            try:
                ipr.link("del", index=_index(ipr, end))
            except (LookupError, NetlinkError) as exc:
                if isinstance(exc, NetlinkError) and exc.code != errno.ENODEV:
                    raise

        self.worker.call(work)
        self.impairer.forget(i, j)

    def set_link_impairment(self, i: int, j: int, imp: Impairment) -> None:
        """Apply `imp` to both directions of link i-j."""
        self.impairer.apply(names.link_end(i, j), imp)
        self.impairer.apply(names.link_end(j, i), imp)

    def set_direction_impairment(self, i: int, j: int, imp: Impairment) -> None:
        """Apply `imp` to frames going from i to j only."""
        self.impairer.apply(names.link_end(i, j), imp)

    def kernel_links(self) -> set[tuple[int, int]]:
        """The links as the kernel has them: pairs (i, j), i < j, with a live veth."""

        def work(ipr) -> set[tuple[int, int]]:
            pairs = set()
            for link in ipr.get_links():
                parsed = names.parse_link_end(link.get_attr("IFLA_IFNAME"))
                if parsed:
                    i, j = parsed
                    pairs.add((min(i, j), max(i, j)))
            return pairs

        return self.worker.call(work)
