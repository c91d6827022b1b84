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
