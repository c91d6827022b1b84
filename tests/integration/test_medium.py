"""The radio medium in real namespaces: who hears whom, moves, silence, isolation."""

import json
import os
import random
import sys
import time

import pytest

from topology import names
from topology.network import Network
from topology.radio.ranges import wanted_links
from topology.spec import NetworkSpec, layout_positions

PORT = 47000
PROBE = [sys.executable, "-m", "tests.integration.probe"]
REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _start_listeners(net: Network, tmp_path) -> dict[int, str]:
    outs = {}
    for k in net.spec.robot_ids():
        out = str(tmp_path / f"r{k}.rx")
        net.spawn(k, PROBE + ["listen", str(PORT), out], role="probe", cwd=REPO)
        outs[k] = out
    deadline = time.monotonic() + 10
    for out in outs.values():
        while not (os.path.exists(out) and open(out).read().startswith("ready")):
            assert time.monotonic() < deadline, "listener did not start"
            time.sleep(0.02)
    return outs


def _received(outs: dict[int, str], tag: str) -> dict[int, set[str]]:
    """robot -> set of source addresses from which it received datagrams tagged `tag`."""
    got = {}
    for k, out in outs.items():
        srcs = set()
        for line in open(out).read().splitlines()[1:]:
            src, payload = line.split(" ", 1)
            if payload.startswith(tag + ":"):
                srcs.add(src)
        got[k] = srcs
    return got


def _neighbour_routes(net: Network) -> None:
    """routing none: give every robot a /32 route to every other robot through wlan0, so a
    unicast reaches its destination exactly when the two are linked (ARP answers or not)."""
    n = net.spec.robots
    for k in net.spec.robot_ids():
        batch = "".join(
            f"route add {names.robot_addr(j)}/32 dev wlan0 scope link\n"
            for j in range(1, n + 1)
            if j != k
        )
        r = net.exec(k, ["ip", "-batch", "-"], input=batch, text=True, capture_output=True)
        assert r.returncode == 0, r.stderr


def _check_exact_reachability(net: Network, outs: dict[int, str], round_tag: str) -> None:
    n = net.spec.robots
    expected = wanted_links(net.positions, net.spec.comm_range)
    linked = {k: set() for k in net.spec.robot_ids()}
    for i, j in expected:
        linked[i].add(j)
        linked[j].add(i)
    assert net.links() == set(expected)
    # Start every round with empty ARP caches: an entry still INCOMPLETE from the last round
    # (ARP retries for 3 s) would hold datagrams back; that is ARP's timing, not the medium's.
    for k in net.spec.robot_ids():
        net.exec(k, ["ip", "neigh", "flush", "all"])
    for i in net.spec.robot_ids():
        others = [names.robot_addr(j) for j in range(1, n + 1) if j != i]
        bc = net.exec(i, PROBE + ["send", str(PORT), "255.255.255.255", "--tag",
                                  f"b{round_tag}{i}"], cwd=REPO)  # fmt: skip
        uc = net.exec(i, PROBE + ["send", str(PORT), *others, "--count", "3", "--gap", "0.05",
                                  "--tag", f"u{round_tag}{i}"], cwd=REPO)  # fmt: skip
        assert bc.returncode == 0 and uc.returncode == 0

    def heard() -> dict[int, tuple[set[int], set[int]]]:
        """sender -> (robots that heard its broadcast, robots that got its unicast)."""
        got = {}
        for i in net.spec.robot_ids():
            src = names.robot_addr(i)
            # A socket hears its own broadcasts (the kernel loops them back): not the medium's.
            b = {k for k, s in _received(outs, f"b{round_tag}{i}").items() if src in s and k != i}
            u = {k for k, s in _received(outs, f"u{round_tag}{i}").items() if src in s}
            got[i] = (b, u)
        return got

    # Until every linked robot wrote down what it got (a loaded machine may take a while),
    # then as long again for a datagram that should not have arrived to show up.
    start, deadline = time.monotonic(), time.monotonic() + 20
    while not all(b >= linked[i] and u >= linked[i] for i, (b, u) in heard().items()):
        if time.monotonic() > deadline:
            break
        time.sleep(0.05)
    time.sleep(max(0.5, time.monotonic() - start))
    for i, (bcast, ucast) in heard().items():
        assert bcast == linked[i], f"broadcast from r{i} reached {sorted(bcast)}"
        assert ucast == linked[i], f"unicast from r{i} reached {sorted(ucast)}"


@pytest.mark.parametrize("seed", [1, 2])
def test_random_layout_broadcast_and_unicast_reach_exactly_the_robots_in_range(
    tb_name, tmp_path, seed
):
    positions = layout_positions("random", 7, 6.0, seed=seed)
    spec = NetworkSpec(name=tb_name, positions=tuple(positions), comm_range=7.0)
    with Network(spec) as net:
        assert 0 < len(net.links()) < 21, "layout should be neither empty nor complete"
        _neighbour_routes(net)
        outs = _start_listeners(net, tmp_path)
        _check_exact_reachability(net, outs, "a")
        rng = random.Random(seed)
        for k in rng.sample(list(net.spec.robot_ids()), 3):
            net.move(k, (rng.uniform(0, 16), rng.uniform(0, 16)))
        _check_exact_reachability(net, outs, "b")


def test_removing_a_link_is_silent_wlan0_stays_up(tb_name):
    spec = NetworkSpec(name=tb_name, positions=((0, 0), (5, 0)), comm_range=10.0)
    with Network(spec) as net:
        assert net.links() == {(1, 2)}
        added, removed = net.move(2, (50, 0))
        assert (added, removed) == ([], [(1, 2)])
        assert net.medium.kernel_links() == set()
        for k in (1, 2):
            out = net.exec(k, ["ip", "-j", "link", "show", "wlan0"], capture_output=True, text=True)
            link = json.loads(out.stdout)[0]
            assert "UP" in link["flags"] and "LOWER_UP" in link["flags"]
            assert link["operstate"] == "UP"


def test_two_testbeds_at_once_do_not_interfere(tb_name, tmp_path):
    other = tb_name[:-1] + ("b" if tb_name[-1] != "b" else "c")
    from tests.integration.conftest import _made

    _made.append(other)
    a = NetworkSpec(name=tb_name, positions=((0, 0), (5, 0)), comm_range=10.0)
    b = NetworkSpec(name=other, positions=((0, 0), (50, 0)), comm_range=10.0)
    try:
        with Network(a) as na, Network(b) as nb:
            assert na.links() == {(1, 2)} and nb.links() == set()
            for net in (na, nb):
                _neighbour_routes(net)
            ok_a = na.exec(1, ["ping", "-c1", "-W1", "10.0.0.2"], capture_output=True)
            ok_b = nb.exec(1, ["ping", "-c1", "-W1", "10.0.0.2"], capture_output=True)
            assert ok_a.returncode == 0, "testbed a: its two robots are linked"
            assert ok_b.returncode != 0, "testbed b: same addresses, but not linked"
            nb.move(2, (3, 0))
            na.move(2, (40, 0))
            assert na.links() == set() and nb.links() == {(1, 2)}
            # The failed ping left 10.0.0.2's ARP entry INCOMPLETE (ARP retries for 3 s); a
            # ping queued behind it may wait past -W1 for the next probe. Start from no entry.
            nb.exec(1, ["ip", "neigh", "flush", "all"])
            assert (
                nb.exec(1, ["ping", "-c1", "-W1", "10.0.0.2"], capture_output=True).returncode == 0
            )
    finally:
        from topology.network import destroy

        destroy(other)


def test_robot_namespace_settings(tb_name):
    spec = NetworkSpec(name=tb_name, positions=((0, 0),), comm_range=10.0)
    with Network(spec) as net:

        def sysctl(key):
            r = net.exec(1, ["sysctl", "-n", key], capture_output=True, text=True)
            return r.stdout.strip()

        assert sysctl("net.ipv4.ip_forward") == "1"
        for key in ("all.send_redirects", "wlan0.send_redirects", "all.accept_redirects",
                    "wlan0.accept_redirects", "all.rp_filter", "wlan0.rp_filter"):  # fmt: skip
            assert sysctl(f"net.ipv4.conf.{key}") == "0", key
        addrs = net.exec(1, ["ip", "-j", "addr", "show", "wlan0"], capture_output=True, text=True)
        info = json.loads(addrs.stdout)[0]["addr_info"]
        assert {(a["local"], a["prefixlen"]) for a in info if a["family"] == "inet"} == {
            ("10.0.0.1", 32)
        }
        assert any(a["family"] == "inet6" and a["local"].startswith("fe80") for a in info)
        routes = net.exec(1, ["ip", "-j", "route", "show"], capture_output=True, text=True)
        assert json.loads(routes.stdout) == [], "no subnet route: routes belong to routing"
        lo = net.exec(1, ["ip", "-j", "link", "show", "lo"], capture_output=True, text=True)
        assert "UP" in json.loads(lo.stdout)[0]["flags"]


def test_route_query_reads_each_kernels_next_hop(tb_name):
    """topology.kernel.routequery (the view's click, the oracle bench): one RTM_GETROUTE per ask,
    answered from the kernel's routes that the oracle wrote."""
    from topology.kernel import netns, routequery, rtnl

    spec = NetworkSpec(name=tb_name, positions=((0, 0), (8, 0), (16, 0)), comm_range=10.0,
                       routing="oracle")  # fmt: skip
    with Network(spec) as net:
        socks = {k: netns.run_in(names.robot_ns(tb_name, k), rtnl.open_socket) for k in (1, 3)}
        try:
            assert routequery.next_hop(socks[1], names.robot_addr(3)) == 2
            assert routequery.next_hop(socks[1], names.robot_addr(2)) == 2
            assert routequery.next_hop(socks[3], names.robot_addr(1)) == 2
            route = routequery.lookup(socks[1], names.robot_addr(3))
            assert route is not None and route.gateway == names.robot_addr(2)
            net.move(3, (60, 0))
            assert routequery.next_hop(socks[1], names.robot_addr(3)) is None
            assert routequery.next_hop(socks[3], names.robot_addr(1)) is None
        finally:
            for s in socks.values():
                s.close()
