"""A lone robot beside ordinary neighbours on the machine: is its run still exact and
faithful, and how late was each kind of process?

Theory of operation
-------------------
A shared machine (a CI virtual machine, a lab server) runs other work beside the testbed. Three
neighbours stand for the usual kinds, each started before the run and stopped after it, each
at a lower priority than the run's, as a polite neighbour would be:

- `disk`: a writer that writes DISK_MB and syncs it, in a loop (dd with conv=fsync, niced);
- `churn`: another testbed's network of CHURN_ROBOTS robots brought up and torn down in a
  loop (`testbed net up` / `down`, niced: namespaces, veths, AODV daemons, their deletion);
- `busy`: two niced busy loops, one a core.

`none` is the same run with no neighbour. The run is a lone robot of seed S at time scale 5
(the exactness test's runs, tests/integration/test_lone_exactness.py): exact means the same
steps and positions.csv as tests/data/lone-k5. The benchmark (`python -m testbed.bench
neighbours`) runs each neighbour RUNS times and writes results/bench/neighbours.json: per
neighbour, how many runs were exact and faithful, and the worst lateness of each kind of
process (the world's step loop, the robot's plans and plan timers, the AODV daemons' HELLO
and expiry timers, the display's frames) with the host stalls the world saw.
tests/integration/test_neighbours.py runs each neighbour once, at one seed, and asks for exact
and faithful.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import uuid
from collections.abc import Iterator

from testbed import PROJECT_ROOT
from testbed.bench.common import write

KINDS = ("none", "disk", "churn", "busy")
DISK_MB = 1500  # written and synced each round of the disk writer
CHURN_ROBOTS = 10
NICE = 10
TIME_SCALE = 5.0
DATA = os.path.join(PROJECT_ROOT, "tests", "data", "lone-k5")
STEPS = {1: 1901, 2: 1989, 3: 1964}  # a lone robot's steps at time scale 5 (the exactness test)
RUNS = 3


def _loop(argv_lines: list[str]) -> subprocess.Popen:
    """A niced shell loop of its own process group (so that stopping it stops its children)."""
    script = "while :; do " + "; ".join(argv_lines) + "; done"
    return subprocess.Popen(
        ["nice", "-n", str(NICE), "sh", "-c", script],
        start_new_session=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )


def _stop(proc: subprocess.Popen) -> None:
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGTERM)
    try:
        proc.wait(timeout=20)
    except subprocess.TimeoutExpired:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


@contextlib.contextmanager
def neighbour(kind: str, scratch: str) -> Iterator[None]:
    """`kind` running beside the block (files in `scratch`); stopped and cleaned after it,
    however the block ends."""
    if kind not in KINDS:
        raise ValueError(f"no neighbour {kind!r} (there are: {', '.join(KINDS)})")
    procs: list[subprocess.Popen] = []
    name = "nb" + uuid.uuid4().hex[:6]
    testbed = [sys.executable, "-m", "testbed", "net"]
    try:
        if kind == "disk":
            big = os.path.join(scratch, "neighbour.bin")
            procs.append(_loop([f"dd if=/dev/zero of={big} bs=1M count={DISK_MB} conv=fsync "
                                "status=none", f"rm -f {big}"]))  # fmt: skip
        elif kind == "churn":
            up = [*testbed, "up", name, "--robots", str(CHURN_ROBOTS), "--comm-range", "10"]
            down = [*testbed, "down", name]
            procs.append(_loop([" ".join(up), " ".join(down)]))
        elif kind == "busy":
            procs += [_loop([":"]), _loop([":"])]
        time.sleep(2.0 if procs else 0.0)  # the neighbour under way before the run starts
        yield
    finally:
        for p in procs:
            _stop(p)
        if kind == "churn":
            subprocess.run([*testbed, "down", name], capture_output=True, check=False)


def lone_run(seed: int, out: str, robot: str = "auto") -> dict:
    """A lone robot of `seed` at TIME_SCALE into `out`: result.json's numbers that say how
    late each kind of process was, and whether the run was exact."""
    from testbed.run.execute import RunConfig, run
    from topology.network import destroy

    name = "nr" + uuid.uuid4().hex[:6]
    cfg = RunConfig(robots=1, comm_range=20.0, laser_range=2.0, seed=seed,
                    time_scale=TIME_SCALE, robot=robot)  # fmt: skip
    try:
        r = run(cfg, out, name, progress=False).to_json()
    finally:
        destroy(name)
    return summarise(r, out, seed)


def summarise(r: dict, out: str, seed: int) -> dict:
    """What one run says per kind of process, and whether it was exact."""
    m = r["fidelity"]["measures"]
    with open(os.path.join(out, "positions.csv")) as f:
        same_path = f.read() == _expected(seed)
    return {
        "seed": seed,
        "steps": r["steps"],
        "exact": r["steps"] == STEPS.get(seed) and same_path,
        "faithful": bool(r["fidelity"]["ok"]),
        "robot": r.get("robot"),
        "world": {
            "deadlines_missed_world": r.get("deadlines_missed_world"),
            "worst_ms_late": max(
                (ms for _, ms in r.get("world_missed_steps_ms_late") or []), default=0.0
            ),  # fmt: skip
            "time_scale_achieved": r.get("time_scale_achieved"),
            "host_stalls": r.get("host_stalls"),
        },
        "robot_process": {
            "deadline_miss_fraction": m.get("deadline_miss_fraction"),
            "late_plans": m.get("late_plans"),
            "late_timers": m.get("late_timers"),
            "late_dones": m.get("late_dones"),
        },
        "aodv": {
            "hello_late_max_ms": m.get("hello_late_max_ms"),
            "expiry_late_max_ms": m.get("expiry_late_max_ms"),
        },  # fmt: skip
        "display": {"late_frames": m.get("display_late_frames")},
    }


def _expected(seed: int) -> str | None:
    path = os.path.join(DATA, f"seed{seed}.positions.csv")
    if not os.path.exists(path):
        return None
    with open(path) as f:
        return f.read()


def measure(kinds: tuple[str, ...] = KINDS, seeds: tuple[int, ...] = (1, 2, 3)) -> dict:
    out: dict = {"time_scale": TIME_SCALE, "loadavg_before": os.getloadavg(), "neighbours": {}}
    for kind in kinds:
        runs = []
        for seed in seeds[:RUNS]:
            scratch = tempfile.mkdtemp(prefix="bench-nb-")
            try:
                with neighbour(kind, scratch):
                    runs.append(lone_run(seed, os.path.join(scratch, "run")))
            finally:
                shutil.rmtree(scratch, ignore_errors=True)
        out["neighbours"][kind] = {
            "exact_and_faithful": sum(r["exact"] and r["faithful"] for r in runs),
            "runs": len(runs),
            "hello_late_max_ms": max(r["aodv"]["hello_late_max_ms"] or 0 for r in runs),
            "late_plans": sum(r["robot_process"]["late_plans"] or 0 for r in runs),
            "host_stalled_s": round(sum(r["world"]["host_stalls"]["stalled_s"] for r in runs), 3),
            "each": runs,
        }
    return out


def run() -> None:
    result = measure()
    write("neighbours", result)
    print(json.dumps({k: {x: v[x] for x in v if x != "each"}
                      for k, v in result["neighbours"].items()}, indent=1))  # fmt: skip
