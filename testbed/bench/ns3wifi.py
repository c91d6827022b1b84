"""Benchmark of the ns3-wifi medium (topology.radio.ns3wifi): what the ns-3 process costs and how
late it runs.

- size: 10, 20 and 50 robots at time scale 1 on a square room (grid, 4 m apart, range 20 m),
  each broadcasting a 1000-byte datagram every 100 ms of emulated time (a flooded map
  fragment's size and the exploration's map period), every robot moved a little each step
  (100 ms) through Network.set_positions, for SECONDS. Reported: the process's CPU (share
  of one core), the relay lag and the timer lateness (topology.radio.ns3wifi counters), what
  arrived, and the round trip of a position update.
- scale: 10 robots, the same traffic, at time scales 1, 2, 5, 10 and 20 (emulated periods
  divided by K). The highest faithful time scale is the highest K whose relay lag stays
  below 1 ms of emulated time for 99% of the frames and whose MAC queues dropped nothing.

The traffic comes from this process: one UDP socket per robot, made inside its namespace,
written in turn at each period; no process per robot.
"""

import os
import random
import socket
import time
import uuid

from testbed.bench.common import median, write
from topology import state
from topology.kernel import netns
from topology.names import robot_ns
from topology.network import Network
from topology.radio.ns3wifi import Ns3Medium, binary
from topology.spec import NetworkSpec, layout_positions

SECONDS = float(os.environ.get("BENCH_NS3_SECONDS", "10"))
SIZES = (10, 20, 50)
SCALES = (1.0, 2.0, 5.0, 10.0, 20.0)
PERIOD_S = 0.1  # emulated: one broadcast per robot, one position update
PAYLOAD = b"m" * 1000
PORT = 47011
SO_BINDTODEVICE = 25


def _socket() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
    s.setsockopt(socket.SOL_SOCKET, SO_BINDTODEVICE, b"wlan0")
    return s


def _cpu_s(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def measure(robots: int, time_scale: float) -> dict:
    name = "bn" + uuid.uuid4().hex[:6]
    positions = layout_positions("grid", robots, 4.0)
    spec = NetworkSpec(name, tuple(positions), 20.0, medium="ns3-wifi", time_scale=time_scale)
    rng = random.Random(1)
    with Network(spec) as net:
        st, medium = state.read(name), net.medium
        assert st is not None and isinstance(medium, Ns3Medium)  # up, on ns3-wifi
        pid = next(p.pid for p in st.processes if p.role == "ns3-wifi")
        socks = [netns.run_in(robot_ns(name, k), _socket) for k in spec.robot_ids()]
        try:
            period = PERIOD_S / time_scale
            before = medium.counters()
            cpu0, t0 = _cpu_s(pid), time.monotonic()
            rtts = []
            next_at = t0
            while next_at < t0 + SECONDS:
                for s in socks:
                    s.sendto(PAYLOAD, ("255.255.255.255", PORT))
                moved = [(x + rng.uniform(-0.05, 0.05), y + rng.uniform(-0.05, 0.05))
                         for x, y in net.positions]  # fmt: skip
                t = time.perf_counter()
                net.set_positions(moved)
                rtts.append(time.perf_counter() - t)
                next_at += period
                time.sleep(max(0.0, next_at - time.monotonic()))
            wall = time.monotonic() - t0
            cpu = _cpu_s(pid) - cpu0
            time.sleep(0.2)  # what is still on the air arrives
            after = medium.counters()
        finally:
            for s in socks:
                s.close()

    def total(c: dict, key: str) -> int:
        return sum(r[key] for r in c["robots"])

    sent = total(after, "from_linux") - total(before, "from_linux")
    relay = after["relay_lag"]
    return {
        "robots": robots,
        "time_scale": time_scale,
        "seconds": round(wall, 2),
        "cpu_share_of_a_core": round(cpu / wall, 4),
        "frames_sent": sent,
        "frames_delivered": total(after, "to_linux") - total(before, "to_linux"),
        "queue_drops": total(after, "queue_drops"),
        "relay_lag_emulated_ms": {k: relay[k] for k in ("mean_ms", "max_ms")},
        "relay_lag_over_1ms_share": round(relay["over_1ms"] / max(1, relay["frames"]), 4),
        "lateness_emulated_ms": {k: after["lateness"][k] for k in ("mean_ms", "max_ms")},
        "position_update_ms_median": round(1000 * median(rtts), 3),
    }


def faithful(row: dict) -> bool:
    return row["relay_lag_over_1ms_share"] < 0.01 and row["queue_drops"] == 0


def run() -> None:
    if not os.access(binary(), os.X_OK):
        raise RuntimeError(f"{binary()} is not built: run `sudo make setup`")
    sizes = [measure(n, 1.0) for n in SIZES]
    for row in sizes:
        print(f"ns3-wifi: {row['robots']} robots: ns-3 {100 * row['cpu_share_of_a_core']:.1f}% "
              f"of a core, relay lag mean {row['relay_lag_emulated_ms']['mean_ms']:.3f} ms "
              f"(over 1 ms: {100 * row['relay_lag_over_1ms_share']:.2f}%)")  # fmt: skip
    scales = [measure(10, k) for k in SCALES]
    highest = None
    for row in scales:  # in increasing order: the last before the first unfaithful one
        if not faithful(row):
            break
        highest = row["time_scale"]
    print(f"ns3-wifi: highest faithful time scale for 10 robots: {highest}")
    path = write("ns3wifi", {"sizes": sizes, "scales": scales,
                             "highest_faithful_time_scale_10_robots": highest})  # fmt: skip
    print(f"ns3-wifi: {path}")
