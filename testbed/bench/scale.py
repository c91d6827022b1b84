"""Benchmark of large teams: bring-up and teardown at 100, 500 and 1000 robots, 500 AODV
robots (pairs reached, memory, idle CPU), and the position feed's rate.

- bring-up: ms per robot of Network.up() on a grid (spacing 8, range 10: four neighbours,
  routing none), at 100, 500 and 1000 robots; teardown: Network.down() of the same, in s.
  The kernel frees a namespace's devices in the background after teardown (cleanup_net) and
  new namespaces are slow to create meanwhile: `kernel_cleanup_s` is how long after down()
  returned that lasted (measured with a probe namespace), and each bring-up waits for it.
- 500 AODV robots on a grid of spacing 8 and range AODV_RANGE = 12, which covers the
  diagonals (eight neighbours): a route across the 23 x 22 grid is then at most 22 hops.
  With range 10 (four neighbours) it is up to 43 hops, beyond RFC 3561's NET_DIAMETER of
  35, so some pairs are out of AODV's reach by design, which no researcher would choose.
  PAIRS random pairs, each pinged until it answers or PING_WAIT_S pass (the failures are
  listed with their hop counts); the daemons' memory (RSS and PSS per daemon, PSS in
  total); their CPU while idle (no traffic) over IDLE_S, in cores.
- feed: a 1000-robot testbed, a FeedServer on it, FEED_UPDATES moves (a random robot, a
  step of up to STEP_M metres each way) written to its socket as fast as one client can:
  updates applied (links updated) per second; and the latency of one move_many of one robot
  (the cost of an unbatched update). A link met for the first time costs a veth pair (a few
  ms of kernel work, topology.radio.veth), so teleports anywhere would be slower.
(The 1,000-robot check with traffic, 30 s of pings a pair, is testbed.bench.aodv_grid; its
idle daemons and their bring-up to routing-ready, testbed.bench.idle.)
Goals: bring-up <= 3 ms per robot at 500, up of 1000 <= 10 s, teardown of 1000
<= 10 s, every pair reached, >= 1000 feed updates per second.
"""

import math
import os
import random
import socket
import threading
import time
import uuid
from typing import Any

from testbed.bench.common import median, memory_kib, write
from topology import names
from topology.inputs import feed
from topology.kernel import netns
from topology.network import Network
from topology.spec import NetworkSpec, layout_positions

PROBE_MS = 10.0
SETTLED_PROBES = 3
PAIRS = 20
PING_WAIT_S = 30.0
IDLE_S = 10.0
FEED_UPDATES = 20000  # a few seconds of feed at the rate reached
STEP_M = 1.0
AODV_RANGE = 12.0


def _name() -> str:
    return "sc" + uuid.uuid4().hex[:6]


def _spec(n: int, routing: str = "none", comm_range: float = 10.0) -> NetworkSpec:
    return NetworkSpec(name=_name(), positions=tuple(layout_positions("grid", n, 8.0)),
                       comm_range=comm_range, routing=routing)  # fmt: skip


def bring_up(n: int) -> dict:
    settle()
    net = Network(_spec(n))
    t0 = time.perf_counter()
    net.up()
    up_s = time.perf_counter() - t0
    links = len(net.links())
    t0 = time.perf_counter()
    net.down()
    down_s = time.perf_counter() - t0
    left = [ns for ns in netns.list_names() if ns.startswith(f"tb-{net.name}-")]
    cleanup_s = settle()
    return {"robots": n, "links": links, "up_s": round(up_s, 3),
            "up_ms_per_robot": round(1000 * up_s / n, 3), "down_s": round(down_s, 3),
            "kernel_cleanup_s": round(cleanup_s, 3), "namespaces_left": len(left)}  # fmt: skip


def settle(limit_s: float = 120.0) -> float:
    """Wait until the kernel has freed the namespaces of earlier testbeds (it does so in the
    background after teardown, and creating a namespace waits for it meanwhile): until a
    probe namespace is created in under PROBE_MS, SETTLED_PROBES times in a row 0.2 s apart
    (one fast probe right after a teardown may come before the kernel's cleanup started).
    Returns the seconds until the last slow probe ended (0 if none was slow)."""
    t0 = time.perf_counter()
    fast, slow_until = 0, 0.0
    while time.perf_counter() - t0 < limit_s and fast < SETTLED_PROBES:
        probe = f"tb-{_name()}-m"
        t = time.perf_counter()
        netns.create(probe)
        netns.remove(probe)
        if (time.perf_counter() - t) * 1000 < PROBE_MS:
            fast += 1
        else:
            fast, slow_until = 0, time.perf_counter() - t0
        time.sleep(0.2)
    return slow_until


def _grid_hops(a: int, b: int, n: int) -> int:
    """Fewest hops from a to b on the grid when diagonal neighbours are linked."""
    cols = math.ceil(math.sqrt(n))
    return max(abs((a - 1) % cols - (b - 1) % cols), abs((a - 1) // cols - (b - 1) // cols))


def _cpu_ticks(pid: int) -> int:
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return int(fields[11]) + int(fields[12])
    except (FileNotFoundError, IndexError):
        return 0


def aodv(n: int = 500) -> dict:
    settle()
    net = Network(_spec(n, "aodv", AODV_RANGE))
    t0 = time.perf_counter()
    net.up()
    up_s = time.perf_counter() - t0
    try:
        assert net.state is not None  # up() made it
        pids = [p.pid for p in net.state.processes if p.role == "aodv"]
        hz = os.sysconf("SC_CLK_TCK")
        before = sum(_cpu_ticks(p) for p in pids)
        time.sleep(IDLE_S)
        idle_cores = (sum(_cpu_ticks(p) for p in pids) - before) / hz / IDLE_S
        mem = [memory_kib(p) for p in pids]
        rss, pss = [m[0] for m in mem], [m[1] for m in mem]
        rng = random.Random(23)
        reached, times, failed, hops = 0, [], [], []
        for _ in range(PAIRS):
            a, b = rng.sample(range(1, n + 1), 2)
            hops.append(_grid_hops(a, b, n))
            t0 = time.monotonic()
            while time.monotonic() - t0 < PING_WAIT_S:
                r = net.exec(a, ["ping", "-c1", "-W2", names.robot_addr(b)],
                             capture_output=True)  # fmt: skip
                if r.returncode == 0:
                    reached += 1
                    times.append(time.monotonic() - t0)
                    break
            else:
                failed.append([a, b, _grid_hops(a, b, n)])
        cols = math.ceil(math.sqrt(n))
        return {"robots": n, "comm_range": AODV_RANGE, "up_s": round(up_s, 3),
                "grid_diameter_hops": max(cols, math.ceil(n / cols)) - 1,
                "max_pair_hops": max(hops), "pairs_tried": PAIRS,
                "pairs_reached": reached, "median_s_to_first_reply": round(median(times), 3)
                if times else None, "daemons": len(pids),
                "failed_pairs_with_grid_hops": failed,
                "rss_mb_per_daemon": round(median(rss) / 1024, 2) if rss else None,
                "pss_mb_total": round(sum(pss) / 1024, 1),
                "pss_mb_per_daemon": round(median(pss) / 1024, 2) if pss else None,
                "idle_cpu_cores": round(idle_cores, 3)}  # fmt: skip
    finally:
        t0 = time.perf_counter()
        net.down()
        print(f"  aodv {n}: down in {time.perf_counter() - t0:.1f} s")


def feed_rate(n: int = 1000) -> dict:
    settle()
    net = Network(_spec(n), persistent=False)
    net.up()
    try:
        rng = random.Random(1)
        t0 = time.perf_counter()
        for _ in range(200):  # one robot a step away and back: no new veth pair
            k = rng.randint(1, n)
            x, y = net.positions[k - 1]
            net.move_many({k: (x + 0.5, y)})
            net.move_many({k: (x, y)})
        single_ms = 1000 * (time.perf_counter() - t0) / 400
        path = os.path.join(net.state_dir, feed.SOCKET_NAME)
        server = feed.FeedServer(net, path, stdin=False)
        stop = threading.Event()
        thread = threading.Thread(target=server.serve, args=(False, stop))
        thread.start()
        # A simulator's stream: each update moves one robot a step of up to STEP_M metres
        # (robots walking), so links change now and then, as on a real team.
        pos = list(net.positions)
        lines = []
        for _ in range(FEED_UPDATES):
            k = rng.randint(1, n)
            x, y = pos[k - 1]
            pos[k - 1] = (x + rng.uniform(-STEP_M, STEP_M), y + rng.uniform(-STEP_M, STEP_M))
            lines.append(f"{k} {pos[k - 1][0]:.3f} {pos[k - 1][1]:.3f}\n")
        links_before = set(net.links())
        t0 = time.perf_counter()
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
            s.connect(path)
            for line in lines:
                s.sendall(line.encode())
            s.shutdown(socket.SHUT_WR)
            s.recv(1)  # the server closes once the last batch is applied
        spent = time.perf_counter() - t0
        stop.set()
        thread.join()
        server.close()
        changed = len(links_before ^ set(net.links()))
        return {"robots": n, "updates": server.lines, "batches": server.batches,
                "links_changed": changed, "step_m": STEP_M,
                "updates_per_s": round(server.lines / spent, 1),
                "single_move_ms": round(single_ms, 3)}  # fmt: skip
    finally:
        net.down()


def run() -> None:
    data: dict[str, Any] = {"bring_up": [bring_up(n) for n in (100, 500, 1000)]}
    for row in data["bring_up"]:
        print(f"  {row['robots']} robots: {row['up_ms_per_robot']} ms/robot, "
              f"up {row['up_s']} s, down {row['down_s']} s")  # fmt: skip
    data["feed"] = feed_rate()
    print(f"  feed: {data['feed']['updates_per_s']} updates/s at 1000 robots")
    data["aodv_500"] = aodv()
    print(f"  aodv 500: {data['aodv_500']['pairs_reached']}/{PAIRS} pairs")
    print(f"scale: {write('scale', data)}")


if __name__ == "__main__":
    run()
