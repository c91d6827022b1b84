"""Benchmark of idle AODV daemons, the Python daemon against the compiled one (issue 53's
targets: one idle daemon at most 0.02% of a core and 2 MiB resident; 1,000 robots up and
routing-ready in at most 10 s).

- idle: a network of IDLE_ROBOTS robots (topology.Network, routing aodv, a grid of spacing 8
  and range 12, so every robot has neighbours; no traffic, no robot programs), left WARMUP_S
  after its bring-up, then each daemon's CPU over IDLE_S (its threads' time on a CPU, in
  nanoseconds, and its waited-for children's: cpu_s) as a percentage of one core, and its
  memory at the end from /proc/PID/smaps_rollup: RSS (resident) and PSS (the Python daemons
  are forked from one fork server, so much of their RSS is pages shared with it and each
  other; PSS charges each shared page in parts). Medians, means and maxima over the daemons,
  for each (daemon, statistics period) of IDLE_CASES: every second, as `net up` runs the
  daemons, and 0 (only when ready, asked and stopping), as `testbed run` does without --view.
- ready: Network.up() of a grid with routing aodv, to its return, which is once every
  daemon has written its statistics file, i.e. has its socket, TUN device and routes ready
  (topology.bringup.start_routing): the time from bring-up to routing-ready, READY_REPEATS
  times for each (robots, daemon) of READY_CASES, after the kernel has freed the earlier
  testbeds' namespaces (scale.settle). The median, the minimum and the maximum.

Each case records the load average and the busiest processes when it started (the machine
is shared). `python -m testbed.bench idle` writes results/bench/idle.json; TESTBED_IDLE_S
and TESTBED_IDLE_REPEATS change the window and the repeats (e.g. for a quick look).
"""

from __future__ import annotations

import os
import sys
import time
import uuid

from testbed.bench.common import busiest_processes, median, memory_kib, write
from testbed.bench.scale import settle
from topology.network import Network, destroy
from topology.spec import NetworkSpec, layout_positions

IDLE_ROBOTS = 100
IDLE_S = 60.0
WARMUP_S = 5.0
SPACING_M = 8.0
RANGE_M = 12.0  # the diagonals too: eight neighbours inside the grid (as scale.AODV_RANGE)
DAEMONS = ("python", "cpp")
# (daemon, its --stats-period): 1 s as `testbed net up` and a run with --view have it, 0 as
# `testbed run` gives the daemons otherwise (the file written when ready, asked and stopping).
IDLE_CASES = (("python", 1.0), ("cpp", 1.0), ("python", 0.0), ("cpp", 0.0))
READY_CASES = ((100, "python"), (100, "cpp"), (1000, "cpp"))
READY_REPEATS = 3
CLK_TCK = os.sysconf("SC_CLK_TCK")
TARGETS = {"cpu_percent_of_core": 0.02, "rss_mib": 2.0, "ready_s_at_1000": 10.0}


def spec(n: int, daemon: str, prefix: str = "ti", stats_period: float = 1.0) -> NetworkSpec:
    return NetworkSpec(
        name=prefix + uuid.uuid4().hex[:6],
        positions=tuple(layout_positions("grid", n, SPACING_M)),
        comm_range=RANGE_M,
        routing="aodv",
        aodv_daemon=daemon,
        aodv_stats_period=stats_period,
    )


def case_name(daemon: str, stats_period: float) -> str:
    """An idle case's key in the JSON: the daemon, and `-stats0` for --stats-period 0."""
    return daemon if stats_period == 1.0 else f"{daemon}-stats{stats_period:g}"


def cpu_s(pid: int) -> float | None:
    """CPU seconds of pid: its threads' time on a CPU in nanoseconds (/proc/PID/task/*/
    schedstat; /proc/PID/stat counts in clock ticks of 10 ms, and an idle daemon uses one
    or two a minute), and its waited-for children's (stat, in ticks). None once it is gone."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        ns = 0
        for tid in os.listdir(f"/proc/{pid}/task"):
            with open(f"/proc/{pid}/task/{tid}/schedstat") as f:
                ns += int(f.read().split()[0])
    except (OSError, ValueError, IndexError):
        return None
    return ns / 1e9 + (int(fields[13]) + int(fields[14])) / CLK_TCK


def daemon_pids(net: Network) -> list[int]:
    assert net.state is not None  # up() made it
    return [p.pid for p in net.state.processes if p.role == "aodv"]


def machine() -> dict:
    return {"load_average_1min": os.getloadavg()[0], "busiest": busiest_processes()}


def idle(daemon: str, n: int = IDLE_ROBOTS, window_s: float = IDLE_S,
         stats_period: float = 1.0) -> dict:  # fmt: skip
    """The idle daemons of one n-robot network, over window_s."""
    settle()
    s = spec(n, daemon, stats_period=stats_period)
    at_start = machine()
    try:
        net = Network(s)
        t0 = time.perf_counter()
        net.up()
        ready_s = time.perf_counter() - t0
        try:
            pids = daemon_pids(net)
            time.sleep(WARMUP_S)
            before = {p: cpu_s(p) for p in pids}
            t0 = time.monotonic()
            time.sleep(window_s)
            dt = time.monotonic() - t0
            after = {p: cpu_s(p) for p in pids}
            mem = [memory_kib(p) for p in pids]
        finally:
            net.down()
    finally:
        destroy(s.name)
    spent = [
        (b, a) for b, a in ((before[p], after[p]) for p in pids) if b is not None and a is not None
    ]
    cpu = [100 * (a - b) / dt for b, a in spent]
    rss = [m[0] / 1024 for m in mem if m[0]]
    pss = [m[1] / 1024 for m in mem if m[0]]
    return {
        "daemon": daemon, "stats_period_s": stats_period, "robots": n, "daemons": len(pids),
        "daemons_alive": len(spent),
        "machine_at_start": at_start, "ready_s": round(ready_s, 3), "window_s": round(dt, 2),
        "cpu_percent_of_core_median": round(median(cpu), 4) if cpu else None,
        "cpu_percent_of_core_max": round(max(cpu), 4) if cpu else None,
        "cpu_percent_of_core_mean": round(sum(cpu) / len(cpu), 4) if cpu else None,
        "cpu_percent_of_core_all_daemons": round(sum(cpu), 3),
        "rss_mib_median": round(median(rss), 3) if rss else None,
        "rss_mib_max": round(max(rss), 3) if rss else None,
        "pss_mib_median": round(median(pss), 3) if pss else None,
        "pss_mib_total": round(sum(pss), 1),
    }  # fmt: skip


def ready(n: int, daemon: str, repeats: int = READY_REPEATS) -> dict:
    """Bring-up to routing-ready of n robots, `repeats` times."""
    times, downs, loads = [], [], []
    for _ in range(repeats):
        settle()
        loads.append(machine())
        s = spec(n, daemon)
        try:
            net = Network(s)
            t0 = time.perf_counter()
            net.up()
            times.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            net.down()
            downs.append(time.perf_counter() - t0)
        finally:
            destroy(s.name)
    return {
        "robots": n, "daemon": daemon, "ready_s": [round(t, 3) for t in times],
        "ready_s_median": round(median(times), 3), "ready_s_min": round(min(times), 3),
        "ready_s_max": round(max(times), 3), "down_s_median": round(median(downs), 3),
        "machine_at_starts": loads,
    }  # fmt: skip


def targets(idles: dict[str, dict], readies: list[dict]) -> dict:
    out: dict[str, dict] = {}
    for daemon, r in idles.items():
        cpu, rss = r["cpu_percent_of_core_median"], r["rss_mib_median"]
        out[f"idle_cpu_percent_{daemon}"] = {
            "target": TARGETS["cpu_percent_of_core"], "measured": cpu,
            "met": cpu is not None and cpu <= TARGETS["cpu_percent_of_core"],
        }  # fmt: skip
        out[f"idle_rss_mib_{daemon}"] = {
            "target": TARGETS["rss_mib"], "measured": rss,
            "met": rss is not None and rss <= TARGETS["rss_mib"],
        }  # fmt: skip
    for r in readies:
        if r["robots"] == 1000:
            out[f"ready_s_1000_{r['daemon']}"] = {
                "target": TARGETS["ready_s_at_1000"], "measured": r["ready_s_median"],
                "met": r["ready_s_median"] <= TARGETS["ready_s_at_1000"],
            }  # fmt: skip
    return out


def _env_number(name: str, default: float) -> float:
    text = os.environ.get(name)
    if text is None:
        return default
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if value <= 0:
        print(f"bench idle: {name}={text[:20]!r} is not a positive number", file=sys.stderr)
        sys.exit(2)
    return value


def run() -> dict:
    window = _env_number("TESTBED_IDLE_S", IDLE_S)
    repeats = int(_env_number("TESTBED_IDLE_REPEATS", READY_REPEATS))
    idles = {}
    for daemon, period in IDLE_CASES:
        name = case_name(daemon, period)
        idles[name] = r = idle(daemon, IDLE_ROBOTS, window, period)
        print(f"  idle {name}: {r['cpu_percent_of_core_median']} % of a core (median, max "
              f"{r['cpu_percent_of_core_max']}), RSS {r['rss_mib_median']} MiB, PSS "
              f"{r['pss_mib_median']} MiB, ready in {r['ready_s']} s")  # fmt: skip
    readies = []
    for n, daemon in READY_CASES:
        readies.append(r := ready(n, daemon, repeats))
        print(f"  ready {n} {daemon}: {r['ready_s_median']} s (median of {repeats})")
    data = {"idle": idles, "ready": readies, "targets": targets(idles, readies)}
    print(f"bench idle: {write('idle', data)}")
    return data
