"""Benchmark of AODV at scale with traffic: ROBOTS robots on a grid, PAIRS random pairs at least
MIN_HOPS hops apart pinging each other for PING_S seconds, the fraction of pings delivered
(issue 53's target: 1,000 robots, at least 99.9%).

The grid: spacing 8 m, range 12 m, so a robot's neighbours include the diagonals and a route
across the 32 x 32 grid of 1,000 is at most 31 hops, within RFC 3561's NET_DIAMETER of 35
(scale.py's 500-robot check chose the same). The daemon is the compiled one unless
TESTBED_GRID_DAEMON says python; TESTBED_GRID_ROBOTS changes the team (e.g. 100 for a quick
look), TESTBED_GRID_RUNS the repeats (a fresh network each; the JSON's median is over them).

Each pair's source runs `ping -n -c COUNT -i INTERVAL_S -W LINGER_S` (COUNT * INTERVAL_S =
PING_S: the last reply waited for up to LINGER_S), all pairs at once, so the discoveries of
the PAIRS routes flood the network together. The first echo of a pair waits in the source
daemon's buffer while its route is found (RFC 3561 6.3: buffered, not dropped), so a pair
loses a ping only if a discovery fails or a route breaks. Delivered = echo replies received
over echo requests sent, summed over the pairs; the pings lost are listed by pair and
sequence number.

Where a shortfall comes from (a profile, recorded in every run): each daemon's CPU over the
ping window (/proc/PID/stat; the busiest five and the sum, in cores), the machine's CPU
busy fraction over it (/proc/stat), and from the daemons' statistics files their timer
lateness books (the worst five timers, daemon and kind) and their discoveries that failed.
The load average and the busiest processes before the bring-up are recorded with each run.
`python -m testbed.bench aodv_grid` writes results/bench/aodv_grid.json.
"""

from __future__ import annotations

import math
import os
import random
import re
import subprocess
import sys
import time

from aodv.statsfile import DaemonStats, StatsError
from testbed.bench.common import median, write
from testbed.bench.idle import cpu_s, daemon_pids, machine, spec
from testbed.bench.scale import settle
from topology import names
from topology.network import Network, destroy
from topology.routing import aodv_stats_file

ROBOTS = 1000
PAIRS = 20
MIN_HOPS = 2
PING_S = 30.0
INTERVAL_S = 0.2
COUNT = round(PING_S / INTERVAL_S)
LINGER_S = 5
SEED = 23
RUNS = 3
TARGET = 0.999
_SEQ = re.compile(rb"icmp_seq=(\d+)")


def grid_hops(a: int, b: int, n: int) -> int:
    """Fewest hops from a to b on the grid (layout_positions' "grid", columns ceil(sqrt(n)))
    when diagonal neighbours are linked."""
    cols = math.ceil(math.sqrt(n))
    return max(abs((a - 1) % cols - (b - 1) % cols), abs((a - 1) // cols - (b - 1) // cols))


def pairs(n: int, count: int, min_hops: int, seed: int) -> list[tuple[int, int]]:
    """`count` random ordered pairs of distinct robots at least min_hops apart, no robot the
    source of two."""
    if count > n - 1:
        raise ValueError(f"{count} pairs need {count + 1} robots or more, not {n}")
    rng = random.Random(seed)
    out: list[tuple[int, int]] = []
    while len(out) < count:
        a, b = rng.sample(range(1, n + 1), 2)
        if grid_hops(a, b, n) >= min_hops and a not in {p[0] for p in out}:
            out.append((a, b))
    return out


def _busy_jiffies() -> tuple[int, int]:
    """(busy, total) jiffies of the whole machine from /proc/stat."""
    with open("/proc/stat") as f:
        v = [int(x) for x in f.readline().split()[1:]]
    idle = v[3] + v[4]
    return sum(v) - idle, sum(v)


def _lateness(net: Network, robots: int) -> tuple[list[list], int, int]:
    """The worst timers of the daemons' lateness books ([robot, kind, max ms, late of n]),
    the daemons' failed discoveries, and the statistics files not readable."""
    worst, failed, unread = [], 0, 0
    for k in range(1, robots + 1):
        try:
            s = DaemonStats.read(aodv_stats_file(k, net.state_dir))
        except (OSError, StatsError, ValueError):
            unread += 1
            continue
        failed += s.discoveries_failed
        for kind, t in (s.timer_lateness_ms or {}).items():
            worst.append([f"r{k}", kind, t.get("max", 0), f"{t.get('late', 0)}/{t.get('n', 0)}"])
    worst.sort(key=lambda w: -w[2])
    return worst[:5], failed, unread


def _ping_result(a: int, b: int, proc: subprocess.Popen) -> dict:
    out, _ = proc.communicate()
    got = {int(m) for m in _SEQ.findall(out)}
    m = re.search(rb"(\d+) packets transmitted, (\d+) received", out)
    sent = int(m[1]) if m else 0
    received = int(m[2]) if m else len(got)
    return {"src": a, "dst": b, "sent": sent, "received": received,
            "lost_seq": sorted(set(range(1, sent + 1)) - got)[:20]}  # fmt: skip


def once(n: int, daemon: str, run: int) -> dict:
    settle()
    at_start = machine()
    s = spec(n, daemon, prefix="tg")
    chosen = pairs(n, PAIRS, MIN_HOPS, SEED + run)
    try:
        net = Network(s)
        t0 = time.perf_counter()
        net.up()
        up_s = time.perf_counter() - t0
        try:
            pids = daemon_pids(net)
            cpu0 = {p: cpu_s(p) or 0.0 for p in pids}
            busy0, total0 = _busy_jiffies()
            t0 = time.monotonic()
            argv = ["ping", "-n", "-c", str(COUNT), "-i", str(INTERVAL_S), "-W", str(LINGER_S)]
            procs = [
                (a, b, net.spawn(a, [*argv, names.robot_addr(b)], role="bench",
                                 stdout=subprocess.PIPE, stderr=subprocess.STDOUT))
                for a, b in chosen
            ]  # fmt: skip
            results = [_ping_result(a, b, p) for a, b, p in procs]
            window = time.monotonic() - t0
            busy1, total1 = _busy_jiffies()
            cpu = {p: (cpu_s(p) or cpu0[p]) - cpu0[p] for p in pids}
            worst, failed, unread = _lateness(net, n)
        finally:
            net.down()
    finally:
        destroy(s.name)
    sent = sum(r["sent"] for r in results)
    received = sum(r["received"] for r in results)
    busiest = sorted(cpu.items(), key=lambda kv: -kv[1])[:5]
    return {
        "robots": n, "daemon": daemon, "machine_at_start": at_start, "up_s": round(up_s, 3),
        "pairs": len(results), "pair_hops": [grid_hops(a, b, n) for a, b in chosen],
        "pings_sent": sent, "pings_received": received,
        "delivered": round(received / sent, 5) if sent else None,
        "pairs_all_delivered": sum(1 for r in results if r["sent"] and not r["lost_seq"]),
        "window_s": round(window, 2),
        "profile": {
            "machine_busy_fraction": round((busy1 - busy0) / max(1, total1 - total0), 3),
            "daemons_cpu_cores": round(sum(cpu.values()) / window, 3),
            "busiest_daemons_cpu_s": [[p, round(c, 3)] for p, c in busiest],
            "worst_timers": worst, "discoveries_failed": failed, "stats_unread": unread,
        },
        "by_pair": [r for r in results if r["lost_seq"] or not r["sent"]],
    }  # fmt: skip


def _env_int(name: str, default: int, low: int, high: int) -> int:
    text = os.environ.get(name, str(default))
    if not (text.isascii() and text.isdigit() and low <= int(text) <= high):
        print(f"bench aodv_grid: {name}={text[:20]!r}: a whole number {low}-{high}",
              file=sys.stderr)  # fmt: skip
        sys.exit(2)
    return int(text)


def run() -> dict:
    n = _env_int("TESTBED_GRID_ROBOTS", ROBOTS, PAIRS + 5, 1000)
    runs = _env_int("TESTBED_GRID_RUNS", RUNS, 1, 20)
    daemon = os.environ.get("TESTBED_GRID_DAEMON", "cpp")
    if daemon not in ("cpp", "python"):
        print(f"bench aodv_grid: TESTBED_GRID_DAEMON={daemon[:20]!r}: cpp or python",
              file=sys.stderr)  # fmt: skip
        sys.exit(2)
    rs = []
    for i in range(runs):
        rs.append(r := once(n, daemon, i))
        print(f"  run {i + 1}: {r['pings_received']}/{r['pings_sent']} delivered "
              f"({r['delivered']}), up {r['up_s']} s, daemons {r['profile']['daemons_cpu_cores']}"
              f" cores")  # fmt: skip
    delivered = median([r["delivered"] or 0.0 for r in rs])
    data = {
        "robots": n, "daemon": daemon, "pairs": PAIRS, "min_hops": MIN_HOPS, "ping_s": PING_S,
        "ping_interval_s": INTERVAL_S, "runs": rs, "delivered_median": delivered,
        "target": {"delivered": TARGET, "met": delivered >= TARGET},
    }  # fmt: skip
    print(f"bench aodv_grid: {write('aodv_grid', data)}")
    return data
