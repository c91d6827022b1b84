"""Shared by the benchmarks: where results go, and medians over noisy repeats."""

import json
import os
import platform
import statistics
import subprocess
import time
from collections.abc import Sequence

from testbed import PROJECT_ROOT

BENCH_DIR = os.path.join(PROJECT_ROOT, "results", "bench")


def median(values: Sequence[float]) -> float:
    return statistics.median(values)


def write(name: str, data: dict) -> str:
    """Write results/bench/NAME.json with the machine's description; return the path."""
    os.makedirs(BENCH_DIR, exist_ok=True)
    data = {
        "benchmark": name,
        "when": time.strftime("%Y-%m-%dT%H:%M:%S"),
        "machine": {
            "cpus": os.cpu_count(),
            "kernel": platform.release(),
            "load_average_1min_at_end": os.getloadavg()[0],
        },
        **data,
    }
    path = os.path.join(BENCH_DIR, f"{name}.json")
    with open(path, "w") as f:
        json.dump(data, f, indent=2)
    return path


def busiest_processes(n: int = 8) -> list[str]:
    """The n busiest processes now (`ps -eo pcpu,comm --sort=-pcpu`: CPU % over each one's
    lifetime), the machine's other work written beside a heavy benchmark's numbers."""
    out = subprocess.run(["ps", "-eo", "pcpu,comm", "--sort=-pcpu"], capture_output=True,
                         text=True, check=False).stdout  # fmt: skip
    return [" ".join(line.split()) for line in out.splitlines()[1 : n + 1]]


def memory_kib(pid: int) -> tuple[int, int]:
    """(RSS, PSS) of pid in KiB from /proc/PID/smaps_rollup; (0, 0) once it is gone. Forked
    processes (the Python daemons, from one server) share most of their RSS; PSS charges each
    shared page in parts."""
    rss = pss = 0
    try:
        with open(f"/proc/{pid}/smaps_rollup") as f:
            for line in f:
                if line.startswith("Rss:"):
                    rss = int(line.split()[1])
                elif line.startswith("Pss:"):
                    pss = int(line.split()[1])
    except OSError:
        pass
    return rss, pss
