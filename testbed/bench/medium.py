"""Benchmark of the radio medium: bring-up per robot, link-update latency, teardown.

- bring-up: median of 3 bring-ups each of 10 and of 50 robots (random layout, about four
  neighbours each, routing none), divided by the number of robots;
- link update: from calling Network.move() that creates a link to the first packet forwarded
  over that link (a broadcast sent right after move() returns, received by the far robot),
  median of 100;
- teardown: median time of Network.down() for the same testbeds. The kernel frees a
  namespace's devices in the background after that (cleanup_net) and, while it does, new
  namespaces are slow to create; each bring-up therefore starts SETTLE_S after the last
  teardown, so that it is measured on its own.
Targets: bring-up <= 15 ms per robot at 50 robots; link update <= 2 ms median.
"""

import os
import socket
import sys
import time
import uuid
from typing import Any

from testbed.bench.common import median, write
from topology.kernel import netns
from topology.network import Network
from topology.spec import NetworkSpec, layout_positions

SO_BINDTODEVICE = 25
PORT = 47900
SETTLE_S = 2.0


def _name() -> str:
    return "bm" + uuid.uuid4().hex[:6]


def bring_up(n: int, repeats: int = 3) -> dict:
    ups, downs, links = [], [], []
    for seed in range(repeats):
        spec = NetworkSpec(
            name=_name(), positions=tuple(layout_positions("random", n, 4.5, seed=seed)),
            comm_range=6.0,
        )  # fmt: skip
        net = Network(spec)
        time.sleep(SETTLE_S)
        t0 = time.perf_counter()
        net.up()
        t1 = time.perf_counter()
        links.append(len(net.links()))
        net.down()
        t2 = time.perf_counter()
        ups.append(t1 - t0)
        downs.append(t2 - t1)
    return {
        "robots": n,
        "links_median": median(links),
        "bring_up_s_median": median(ups),
        "bring_up_ms_per_robot_median": 1000 * median(ups) / n,
        "teardown_s_median": median(downs),
        "runs": repeats,
    }


def _udp(ns: str, bind_port: int | None) -> socket.socket:
    def make() -> socket.socket:
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
        s.setsockopt(socket.SOL_SOCKET, SO_BINDTODEVICE, b"wlan0")
        if bind_port:
            s.bind(("0.0.0.0", bind_port))
        return s

    return netns.run_in(ns, make)  # a socket belongs to the namespace it was made in


def link_update(samples: int = 100) -> dict:
    spec = NetworkSpec(name=_name(), positions=((0, 0), (50, 0)), comm_range=10.0)
    lat, timeouts = [], 0
    with Network(spec) as net:
        tx = _udp(net.robot_ns(1), None)
        rx = _udp(net.robot_ns(2), PORT)
        rx.settimeout(1.0)
        for n in range(samples + 5):
            net.move(2, (50, 0))
            t0 = time.perf_counter()
            net.move(2, (5, 0))
            tx.sendto(b"%d" % n, ("255.255.255.255", PORT))
            try:
                while rx.recv(64) != b"%d" % n:
                    pass
            except TimeoutError:
                timeouts += 1
                continue
            if n >= 5:  # the first moves create the veth pair: not a link update
                lat.append(time.perf_counter() - t0)
        tx.close()
        rx.close()
    return {
        "samples": len(lat),
        "timeouts": timeouts,
        "link_update_ms_median": 1000 * median(lat),
        "link_update_ms_p90": 1000 * sorted(lat)[int(0.9 * len(lat))],
    }


def run() -> dict:
    results: dict[str, Any] = {
        "bring_up": [bring_up(10), bring_up(50)],
        "link_update": link_update(),
        "targets": {"bring_up_ms_per_robot_at_50": 15.0, "link_update_ms_median": 2.0},
    }
    at50 = results["bring_up"][1]["bring_up_ms_per_robot_median"]
    results["meets_targets"] = {
        "bring_up": at50 <= 15.0,
        "link_update": results["link_update"]["link_update_ms_median"] <= 2.0,
    }
    path = write("medium", results)
    print(f"medium: bring-up {at50:.1f} ms/robot at 50, link update "
          f"{results['link_update']['link_update_ms_median']:.2f} ms median -> {path}")  # fmt: skip
    return results


if __name__ == "__main__":
    if os.geteuid() != 0:
        sys.exit("bench: needs root (network namespaces): run `sudo make bench`")
    run()
