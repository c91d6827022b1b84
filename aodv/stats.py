"""Counters of one AODV daemon, written as its statistics file (aodv.statsfile.DaemonStats,
atomically: a temporary file renamed)."""

from __future__ import annotations

import heapq
import os
import signal
import time
from collections import Counter

from aodv.statsfile import DaemonStats

STATS_PERIOD = 1.0  # wall seconds between rewrites of the file (--stats-period's default)
TIMER_BOUNDS_MS = (10, 25, 50, 100, 200)  # emulated ms late: histogram bounds
WORST_KEPT = 128  # the most late firings, kept with their times


class TimerLateness:
    """How late one kind of timer fired, in emulated ms: count, maximum and a histogram over
    TIMER_BOUNDS_MS (the same shape as node.lateness, which aodv may not import), and the
    WORST_KEPT most late firings with when each was due and when it fired (CLOCK_MONOTONIC
    seconds, the clock every process of a run shares), so that a run can judge the timers
    that were late while its robots stepped apart from those of its start and end.
    O(log WORST_KEPT) per firing."""

    def __init__(self) -> None:
        self.n = 0
        self.late = 0
        self.max = 0.0
        self.counts = [0] * (len(TIMER_BOUNDS_MS) + 1)
        self.worst: list[tuple[float, float, float]] = []  # a min-heap: (ms late, due, fired)

    def add(self, late_ms: float, due: float, fired: float) -> None:
        self.n += 1
        self.late += late_ms > 0
        self.max = max(self.max, late_ms)
        i = next((i for i, b in enumerate(TIMER_BOUNDS_MS) if late_ms <= b), -1)
        self.counts[i] += 1
        if len(self.worst) < WORST_KEPT:
            heapq.heappush(self.worst, (late_ms, due, fired))
        elif late_ms > self.worst[0][0]:
            heapq.heapreplace(self.worst, (late_ms, due, fired))

    def as_dict(self) -> dict:
        labels = [f"<={b}" for b in TIMER_BOUNDS_MS] + [f">{TIMER_BOUNDS_MS[-1]}"]
        return {
            "n": self.n,
            "late": self.late,
            "max": round(self.max, 3),
            "hist": dict(zip(labels, self.counts, strict=True)),
            # [due, fired, ms late], in the order they were due
            "worst": [
                [round(d, 4), round(f, 4), round(ms, 3)]
                for ms, d, f in sorted(self.worst, key=lambda w: w[1])
            ],
        }


class Stats:
    def __init__(self, robot: str, addr: str) -> None:
        self.robot = robot
        self.addr = addr
        self.started = time.time()
        self.sent: Counter[str] = Counter()
        self.received: Counter[str] = Counter()
        self.bytes_sent = 0
        self.bytes_received = 0
        self.dropped: Counter[str] = Counter()
        # Sent (handed to the kernel) but reported back untransmitted (IP_RECVERR).
        self.not_transmitted: Counter[str] = Counter()
        self.bytes_not_transmitted = 0
        self.route_installs = 0
        self.route_deletes = 0
        self.packets_buffered = 0
        self.packets_released = 0
        self.icmp_unreachable = 0
        self.route_uses = 0
        self.discoveries: list[dict] = []
        self.local_repairs: Counter[str] = Counter()
        # The core's own counters (aodv.core.AodvCore.dropped): what it bounded or refused.
        self.protocol_dropped: Counter[str] = Counter()
        self.routes: dict[str, dict] = {}
        # How late the core's timers fired (emulated ms): the HELLO timer, and the others
        # (route, neighbour, discovery and acknowledgement expiries).
        self.timer_lateness = {"hello": TimerLateness(), "expiry": TimerLateness()}

    def snapshot(self) -> DaemonStats:
        """The counters now, as the statistics file holds them."""
        ok = [d for d in self.discoveries if d["ok"]]
        return DaemonStats(
            robot=self.robot,
            addr=self.addr,
            pid=os.getpid(),
            uptime_s=round(time.time() - self.started, 3),
            messages_sent=dict(self.sent),
            messages_not_transmitted=dict(self.not_transmitted),
            bytes_not_transmitted=self.bytes_not_transmitted,
            messages_received=dict(self.received),
            bytes_sent=self.bytes_sent,
            bytes_received=self.bytes_received,
            dropped=dict(self.dropped),
            protocol_dropped=dict(self.protocol_dropped),
            local_repairs=dict(self.local_repairs),
            routes=self.routes,
            route_installs=self.route_installs,
            route_deletes=self.route_deletes,
            packets_buffered=self.packets_buffered,
            packets_released=self.packets_released,
            icmp_unreachable_sent=self.icmp_unreachable,
            route_use_refreshes=self.route_uses,
            discoveries_ok=len(ok),
            discoveries_failed=len(self.discoveries) - len(ok),
            discoveries=tuple(self.discoveries[-1000:]),
            timer_lateness_ms={k: v.as_dict() for k, v in self.timer_lateness.items()},
            cpu_s=round(time.process_time(), 3),
        )

    def write(self, path: str, *, compact: bool = False) -> None:
        self.snapshot().write(path, compact=compact)


def read_fresh(path: str, proc, timeout: float = 3.0) -> DaemonStats:
    """Ask a running daemon (`proc`, a Popen) for fresh statistics and read them: SIGUSR1
    makes it rewrite `path`; wait for the rewrite (or `timeout`), then read the file."""
    before = os.stat(path).st_mtime_ns
    proc.send_signal(signal.SIGUSR1)
    deadline = time.monotonic() + timeout
    while os.stat(path).st_mtime_ns == before and time.monotonic() < deadline:
        time.sleep(0.005)
    return DaemonStats.read(path)
