"""The AODV daemon's hands: the protocol core's actions carried out on the kernel.

Theory of operation
-------------------
The core (aodv.core) returns actions; `Actuator.execute` carries them out in the core's
order (control messages, route changes, releases and drops, RREP-ACKs):

    Unicast / Broadcast     -> the control channel (aodv.control), to a neighbour or to
                               255.255.255.255
    InstallRoute / Delete   -> rtnetlink (aodv.kernel.KernelRoutes); the kernel's answers
                               are read later by the loop (`read_route_acks`)
    ReleasePackets          -> a raw socket re-sends the buffered packets
    DropPackets             -> ICMP host unreachable to our own sender, through the TUN
    DiscoveryDone           -> a record in the statistics (latencies end when the route
                               is in the kernel)

Before a batch leaves, the counters it may carry are on disk (RFC 6.13, aodv.persist). An
action that fails is counted and the ones after it still run, so the kernel's routes
always follow the core's table.

The control messages leave from the loop's own thread; everything after them that touches
the kernel's routes, with what must follow a route (releases, drops, the discovery's
record), is handed, in the core's order, to one kernel thread (`KernelThread`), which
carries the batches out in the order they came. A route change is an rtnetlink request
that the kernel serves under its network lock (rtnl), held for tens of milliseconds while
another testbed's namespaces are deleted: on the loop, it held the HELLO and expiry timers
back by as much (docs/measurements.md, "The AODV daemons' stalls"). Releases wait for the
installs before them in the same queue, so a released packet always finds its route.
"""

from __future__ import annotations

import logging
import queue
import socket
import threading
import time
from collections.abc import Callable

from aodv.actions import (
    Action,
    Broadcast,
    DeleteRoute,
    DiscoveryDone,
    DropPackets,
    InstallRoute,
    ReleasePackets,
    Unicast,
)
from aodv.control import ControlChannel
from aodv.core import AodvCore
from aodv.icmp import icmp_host_unreachable
from aodv.kernel import KernelError, KernelRoutes, Tun
from aodv.persist import CounterStore
from aodv.stats import Stats
from common.sched import DEADLINE_PRIORITY, raise_priority

log = logging.getLogger("aodv.daemon")


class KernelThread:
    """Carries out the batches handed to it, one after the other, on a thread of its own
    (at the loop's priority: a discovery's route is on its critical path)."""

    def __init__(self) -> None:
        self._jobs: queue.SimpleQueue[Callable[[], None] | None] = queue.SimpleQueue()
        self._thread = threading.Thread(target=self._run, name="aodv-kernel", daemon=True)
        self._thread.start()

    def submit(self, job: Callable[[], None]) -> None:
        self._jobs.put(job)

    def close(self) -> None:
        """Carry out what was handed over, then stop (idempotent)."""
        if self._thread.is_alive():
            self._jobs.put(None)
            self._thread.join()

    def _run(self) -> None:
        raise_priority(*DEADLINE_PRIORITY)
        while (job := self._jobs.get()) is not None:
            try:
                job()
            except Exception:  # a bug must not stop the routes following the core
                log.exception("kernel batch failed")


BROADCAST = "255.255.255.255"


class Actuator:
    def __init__(
        self,
        core: AodvCore,
        control: ControlChannel,
        routes: KernelRoutes,
        raw: socket.socket,
        tun: Tun,
        stats: Stats,
        store: CounterStore | None,
    ) -> None:
        self.core = core
        self.control = control
        self.routes = routes
        self.raw = raw  # re-sends buffered packets
        self.tun = tun
        self.stats = stats
        self.store = store
        self._own = socket.inet_aton(core.addr)
        self.kernel = KernelThread()

    def close(self) -> None:
        """Wait for the kernel thread to carry out what it was handed, and stop it."""
        self.kernel.close()

    def execute(self, actions: list[Action], now: float) -> None:
        if self.store:
            # RFC 6.13: the numbers these messages carry are on disk before they leave.
            self.store.cover(self.core.seq, self.core.rreq_id)
        # In the core's order (AodvCore._finish): control messages, route changes,
        # releases, RREP-ACKs. The control messages leave here; the rest goes to the
        # kernel thread as one batch, in order (RREP-ACKs need no route: they are unicast
        # to a neighbour, MSG_DONTROUTE).
        kernel: list[Action] = []
        for a in actions:
            if isinstance(a, Unicast):
                self.control.send(a.msg, a.dst, a.ttl, socket.MSG_DONTROUTE)
            elif isinstance(a, Broadcast):
                self.control.send(a.msg, BROADCAST, a.ttl, 0)
            else:
                kernel.append(a)
        if kernel:
            self.kernel.submit(lambda: self._kernel_batch(kernel, now))

    def _kernel_batch(self, actions: list[Action], now: float) -> None:
        """Route changes and what follows them, in order (on the kernel thread). Installs
        are rtnetlink writes whose acknowledgements the loop reads later
        (`read_route_acks`). Route changes are logged at DEBUG: at INFO the line cost more
        than the netlink request on a discovery's critical path."""
        stats = self.stats
        routed = now  # when the last route change of this batch was in the kernel
        for a in actions:
            if isinstance(a, InstallRoute):
                if self._route_change(self.routes.install, a.dest, a.next_hop):
                    stats.route_installs += 1
                routed = time.monotonic()
                log.debug("route %s via %s (%d hops)", a.dest, a.next_hop, a.hops)
            elif isinstance(a, DeleteRoute):
                if self._route_change(self.routes.delete, a.dest):
                    stats.route_deletes += 1
                routed = time.monotonic()
                log.debug("route %s deleted", a.dest)
            elif isinstance(a, ReleasePackets):
                for pkt in a.packets:
                    try:
                        self.raw.sendto(pkt, (a.dest, 0))
                        stats.packets_released += 1
                    except OSError as e:
                        stats.dropped["release_failed"] += 1
                        log.warning("re-send to %s failed: %s", a.dest, e)
            elif isinstance(a, DropPackets):
                for pkt in a.packets:
                    if pkt[12:16] == self._own:
                        self.tun.write(icmp_host_unreachable(self.core.addr, pkt))
                        stats.icmp_unreachable += 1
            elif isinstance(a, DiscoveryDone) and a.repair:
                stats.local_repairs["ok" if a.ok else "failed"] += 1
                log.info("local repair of %s %s", a.dest, "succeeded" if a.ok else "failed")
            elif isinstance(a, DiscoveryDone):
                self._discovery_done(a, now, routed)

    def _route_change(self, change: Callable[..., int], *args: str) -> bool:
        """One rtnetlink request; a send the kernel refused is counted, and the batch goes on
        (the kernel's routes follow the core's table for every other change)."""
        try:
            change(*args)
            return True
        except KernelError as e:
            self.stats.dropped["route_send_failed"] += 1
            log.warning("%s", e)
            return False

    def _discovery_done(self, a: DiscoveryDone, now: float, routed: float) -> None:
        # Both latencies end when the route is in the kernel (the core's run to `now`, the
        # install took until `routed`). The round starts when the RREQ that succeeded went
        # to sendto() (the core's round starts at the event that made it send, before the
        # core ran and the RREQ was encoded).
        extra = routed - now
        sent = self.control.rreq_sent.pop(a.dest, None)
        rnd = a.round_latency + extra if sent is None else routed - sent
        self.stats.discoveries.append(
            {
                "dest": a.dest,
                "ok": a.ok,
                "latency_s": round(a.latency + extra, 6),
                "round_latency_s": round(rnd, 6),
                "t": round(time.time(), 3),
            }
        )
        log.info(
            "discovery of %s %s after %.1f ms",
            a.dest,
            "succeeded" if a.ok else "failed",
            1000 * (a.latency + extra),
        )

    def read_route_acks(self) -> None:
        """The kernel's answers to our route changes: a refusal is counted and logged."""
        for failure in self.routes.read_acks():
            self.stats.dropped["kernel_route_error"] += 1
            log.warning("kernel refused %s", failure)
