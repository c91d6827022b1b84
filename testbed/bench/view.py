"""Benchmark of the live view's cost to a run: the same 3-robot run (seed, time scale 10)
REPEATS times with `--view` and a client reading the stream as a browser would, and
REPEATS times without, alternating; the median fraction of step deadlines missed outside
host stalls of each. Target: with the view within 0.5 percentage points of
without.
"""

import os
import socket
import statistics
import tempfile
import threading
import time
import urllib.request
import uuid

from testbed.bench.common import write
from testbed.run.execute import RunConfig
from testbed.run.execute import run as run_once
from topology.network import destroy

REPEATS = 5


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _reader(port: int, stop: threading.Event, frames: list) -> None:
    deadline = time.monotonic() + 60
    while not stop.is_set() and time.monotonic() < deadline:
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/live", timeout=5) as s:
                for line in s:
                    if line.startswith(b"data: "):
                        frames.append(len(line))
                    if stop.is_set():
                        return
        except OSError:
            time.sleep(0.1)


def one(view: bool) -> tuple[float, int]:
    port = _free_port()
    name = "bv" + uuid.uuid4().hex[:6]
    cfg = RunConfig(robots=3, comm_range=10.0, laser_range=2.0, seed=3, time_scale=10.0,
                    routing="aodv", max_steps=3000,
                    view=f"127.0.0.1:{port}" if view else None)  # fmt: skip
    stop = threading.Event()
    frames: list[int] = []
    reader = threading.Thread(target=_reader, args=(port, stop, frames), daemon=True)
    if view:
        reader.start()
    try:
        with tempfile.TemporaryDirectory() as d:
            result = run_once(cfg, os.path.join(d, "run"), name, progress=False)
    finally:
        stop.set()
        destroy(name)
    # Outside host stalls: the machine stopping (testbed.run.stalls) is not the view's doing, and
    # on this shared host it dominated the misses of some runs either way.
    return result.deadline_miss_fraction_outside_stalls, len(frames)


def run_bench() -> dict:
    with_view, without, frames = [], [], []
    for _ in range(REPEATS):
        miss, n = one(True)
        with_view.append(miss)
        frames.append(n)
        without.append(one(False)[0])
    a, b = statistics.median(with_view), statistics.median(without)
    return {
        "repeats": REPEATS,
        "miss_fraction_with_view": with_view,
        "miss_fraction_without": without,
        "frames_received": frames,
        "median_with_view": a,
        "median_without": b,
        "difference_pp": 100 * (a - b),
        "target_pp": 0.5,
    }


def run() -> None:
    result = run_bench()
    write("view", result)
    print(f"view: deadlines missed {100 * result['median_with_view']:.2f}% with the view open, "
          f"{100 * result['median_without']:.2f}% without (medians of {REPEATS}); "
          f"{result['difference_pp']:+.2f} points")  # fmt: skip
