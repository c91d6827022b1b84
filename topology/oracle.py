"""Oracle routing: the topology controller, which knows the link set, routes every robot.

Theory of operation
-------------------
An ideal baseline for the real routing protocols: no control packet ever crosses the
radio, and every robot's kernel holds a shortest path (fewest hops) to every robot it can
reach, installed the moment a link changes. What a protocol does worse than this is its
cost: overhead against zero, delivery and delay against the best a routing can do on the
same links.

`shortest_routes(links, n)` is pure: a breadth-first search from every robot over the
link graph gives, per robot, destination -> (next hop, hops); among equally short paths the
lowest-numbered next hop wins, so the choice is deterministic and does not flap.
`OracleRouter` keeps one rtnetlink socket per robot namespace (a socket belongs to the
namespace it was made in, so one thread serves them all) and, on every `update(links)`,
diffs the new routes against the ones it installed and writes one batch of requests per
robot whose routes changed, waiting for the kernel's acknowledgements, so the routes are in
place when `update` returns. Routes carry protocol number RTPROT_ORACLE
(`ip route show proto 102`): /32 host routes, a neighbour on the link (scope link), a
farther robot via its next hop (onlink, as the robots have /32 addresses and no subnet).
"""

from __future__ import annotations

import socket
import time
from collections import deque
from collections.abc import Iterable

from topology import names
from topology.kernel import netlinkmsg, netns, rtnl

RTPROT_ORACLE = 102
Pair = tuple[int, int]
Routes = dict[int, dict[int, tuple[int, int]]]  # robot -> dest -> (next hop, hops)


def shortest_routes(links: Iterable[Pair], n: int) -> Routes:
    """Per robot 1..n, its fewest-hop route to every robot it can reach."""
    adj: dict[int, list[int]] = {k: [] for k in range(1, n + 1)}
    for i, j in links:
        adj[i].append(j)
        adj[j].append(i)
    for nbrs in adj.values():
        nbrs.sort()
    routes: Routes = {}
    for src in range(1, n + 1):
        table: dict[int, tuple[int, int]] = {}
        first = {src: 0}
        hops = {src: 0}
        queue = deque([src])
        while queue:
            u = queue.popleft()
            for v in adj[u]:
                if v not in hops:
                    hops[v] = hops[u] + 1
                    first[v] = v if u == src else first[u]
                    table[v] = (first[v], hops[v])
                    queue.append(v)
        routes[src] = table
    return routes


def changes(
    old: dict[int, tuple[int, int]], new: dict[int, tuple[int, int]]
) -> tuple[list[tuple[int, int]], list[int]]:
    """(dest, next hop) to install or replace, and dests to delete, for one robot.
    A change of hop count alone needs no kernel change: the route is the same."""
    install = sorted((d, nh) for d, (nh, _) in new.items() if old.get(d, (None,))[0] != nh)
    delete = sorted(d for d in old if d not in new)
    return install, delete


def route_request(dest: int, next_hop: int, oif: int) -> bytes:
    """`ip route replace 10.0.0.D/32 [via 10.0.0.NH onlink] dev wlan0 proto 102`, to be
    acknowledged (a batch numbers its requests)."""
    return netlinkmsg.route_replace(
        names.robot_addr(dest), names.robot_addr(next_hop), oif, RTPROT_ORACLE, ack=True
    )


def delete_request(dest: int) -> bytes:
    """`ip route del 10.0.0.D/32 proto 102`, to be acknowledged."""
    return netlinkmsg.route_delete(names.robot_addr(dest), RTPROT_ORACLE, ack=True)


class OracleRouter:
    """Installs `shortest_routes` of the current links in every robot's namespace."""

    def __init__(
        self, testbed: str, robots: Iterable[int], oif: int, links: Iterable[Pair] = ()
    ) -> None:
        """`links`: the links whose routes are already installed (a process that attaches to
        a running testbed takes over from the one that made it); none for a new network."""
        self.oif = oif
        robots = list(robots)
        self.installed: Routes = shortest_routes(links, max(robots, default=0))
        self.socks: dict[int, socket.socket] = {}
        self.updates = 0
        self.last_update_s = 0.0  # wall time of the newest update() that changed a route
        try:
            for k in robots:
                self.socks[k] = netns.run_in(names.robot_ns(testbed, k), rtnl.open_socket)
                self.installed.setdefault(k, {})
        except BaseException:
            self.close()
            raise

    def update(self, links: Iterable[Pair]) -> int:
        """Bring every robot's routes to the shortest paths over `links`; returns how many
        robots' tables changed. Raises rtnl.NetlinkBatchError if the kernel refused one."""
        t0 = time.perf_counter()
        wanted = shortest_routes(links, max(self.socks, default=0))
        changed = 0
        for k, sock in self.socks.items():
            new = wanted.get(k, {})
            install, delete = changes(self.installed[k], new)
            if not install and not delete:
                self.installed[k] = new
                continue
            batch = rtnl.Batch()
            for d in delete:
                batch.add(delete_request(d), f"r{k}: delete route to r{d}")
            for d, nh in install:
                batch.add(route_request(d, nh, self.oif), f"r{k}: route to r{d} via r{nh}")
            batch.send(sock)
            self.installed[k] = new
            changed += 1
        if changed:
            self.updates += 1
            self.last_update_s = time.perf_counter() - t0
        return changed

    def close(self) -> None:
        for sock in self.socks.values():
            sock.close()
        self.socks.clear()
