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

import os
import signal
import sys
import time

from testbed.view.live import KernelRoutes, LiveFeed, LiveServer
from topology import state
from topology.radio.los import Walls
from topology.radio.ns3wifi import medium_for
from topology.spec import LOS_MODELS

POLL_S = 0.2
READY_FILE = "view.ready"  # in the testbed's run dir, once the view listens


def ready_path(name: str) -> str:
    return os.path.join(state.run_dir(name), READY_FILE)


class Extent:
    """The square the page draws, in metres: every robot seen so far with room for its range
    ring (so none is cut at the edge, wherever `net move` put it, negative coordinates
    included) and the map's picture if there is one. It only grows: the picture does not
    jump as robots move inside it."""

    def __init__(self, comm_range: float, box: tuple[float, float] | None = None) -> None:
        self.margin = comm_range
        self.lo = [0.0, 0.0] if box else None
        self.hi = list(box) if box else None

    def update(self, positions: list) -> bool:
        """Take in the robots' positions; True if the square changed."""
        m = self.margin
        lo = [min(p[i] for p in positions) - m for i in (0, 1)]
        hi = [max(p[i] for p in positions) + m for i in (0, 1)]
        if self.lo is not None and self.hi is not None:  # (set together)
            lo = [min(a, b) for a, b in zip(lo, self.lo, strict=True)]
            hi = [max(a, b) for a, b in zip(hi, self.hi, strict=True)]
        changed = (lo, hi) != (self.lo, self.hi)
        self.lo, self.hi = lo, hi
        return changed

    def _side(self) -> float:
        assert self.lo is not None and self.hi is not None  # update() came first
        return max(20.0, self.hi[0] - self.lo[0], self.hi[1] - self.lo[1])

    def origin(self) -> list[float]:
        """The square's corner, the robots centred in it along its longer side."""
        side = self._side()
        assert self.lo is not None and self.hi is not None  # update() came first
        return [
            round(lo - (side - (hi - lo)) / 2, 3) for lo, hi in zip(self.lo, self.hi, strict=True)
        ]

    def size(self) -> list[float]:
        return [round(self._side(), 3)] * 2


def main(argv: list[str]) -> int:
    if len(argv) != 2:
        print("usage: python -m testbed.view.netview NAME [HOST:]PORT", file=sys.stderr)
        return 2
    name, bind = argv
    try:
        st = state.read(name)
    except state.UntrustedState as exc:
        print(f"netview: {exc}", file=sys.stderr)
        return 2
    if st is None:
        print(f"netview: no testbed named {name!r} is up", file=sys.stderr)
        return 2
    spec = state.spec_from_dict(st.spec)
    medium = medium_for(spec)
    medium.open()
    map_png = spec.map_png if spec.range_model in LOS_MODELS else None
    box = Walls.from_png(map_png, spec.map_cell).size_m if map_png else None
    extent = Extent(spec.comm_range, box)
    extent.update(st.positions)
    meta = {"run": name, "robots": spec.robots, "comm_range": spec.comm_range,
            "origin": extent.origin(), "map_m": extent.size(), "map_img_m": box,
            "time_scale": spec.time_scale, "display": [], "status": "up",
            "steps": 0, "positions": [], "links": [], "coverage": []}  # fmt: skip
    routes = KernelRoutes(name, spec.robots)
    feed = LiveFeed(meta, routes)
    try:
        server = LiveServer(feed, bind, map_png)
    except OSError as exc:
        print(
            f"netview: --view {bind}: cannot listen there: {exc.strerror or exc}", file=sys.stderr
        )
        return 2
    with open(ready_path(name), "w"):
        pass  # `net up` waits for this before it prints the view's address
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    signal.signal(signal.SIGINT, lambda *_: stop.append(1))
    tick = 0
    try:
        while not stop:
            try:
                now = state.read(name)
            except state.UntrustedState as exc:
                print(f"netview: {exc}", file=sys.stderr)
                break
            if now is None:
                break  # the testbed went down
            links = dict.fromkeys(medium.kernel_links())
            if extent.update(now.positions):
                feed.meta = {**feed.meta, "origin": extent.origin(), "map_m": extent.size()}
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
