"""The live view of a network brought up by hand (`testbed net up ... --view [HOST:]PORT`).

`net up` returns at once and leaves the testbed running, so its view is a process of its
own, `python -m testbed.view.netview NAME [HOST:]PORT`, recorded in the testbed's state like
the routing daemons, so that `net down` (or `testbed clean`) stops it by its pid. Every
POLL_S it reads what the testbed already records: the robots' positions from the state file
(`net move` writes them) and the link set from the medium's bridge ports (a netlink dump in
the medium namespace, read only), and publishes them as a frame of the same live page a run
has (testbed.view.live); a click on a robot draws the routes the robots' kernels hold to it.
"""

from __future__ import annotations

import signal
import sys
import time

from testbed.view.live import KernelRoutes, LiveFeed, LiveServer
from topology import state
from topology.ns3medium import medium_for
from topology.spec import LOS_MODELS

POLL_S = 0.2


def _extent(positions: list, comm_range: float) -> list[float]:
    """A square in metres that holds every robot with room for its range circle."""
    far = max([max(x, y) for x, y in positions] + [0.0]) + comm_range
    return [max(20.0, far), max(20.0, far)]


def main(argv: list[str]) -> int:
    if len(argv) != 2:
        print("usage: python -m testbed.view.netview NAME [HOST:]PORT", file=sys.stderr)
        return 2
    name, bind = argv
    st = state.read(name)
    if st is None:
        print(f"netview: no testbed named {name!r} is up", file=sys.stderr)
        return 2
    spec = state.spec_from_dict(st.spec)
    medium = medium_for(spec)
    medium.open()
    map_png = spec.map_png if spec.range_model in LOS_MODELS else None
    meta = {"run": name, "robots": spec.robots, "comm_range": spec.comm_range,
            "map_m": _extent(st.positions, spec.comm_range), "display": [], "status": "up",
            "steps": 0, "positions": [], "links": [], "coverage": []}  # fmt: skip
    routes = KernelRoutes(name, spec.robots)
    feed = LiveFeed(meta, routes)
    server = LiveServer(feed, bind, map_png)
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    signal.signal(signal.SIGINT, lambda *_: stop.append(1))
    tick = 0
    try:
        while not stop:
            now = state.read(name)
            if now is None:
                break  # the testbed went down
            links = dict.fromkeys(medium.kernel_links())
            tick += 1
            feed.publish(tick, [tuple(p) for p in now.positions], links, None, 0, None)
            time.sleep(POLL_S)
    finally:
        server.stop()
        routes.close()
        medium.close()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
