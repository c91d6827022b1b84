"""A lone robot beside ordinary neighbours on the machine: is its run still exact and
faithful, and how late was each kind of process?

Theory of operation
-------------------
A shared machine (a CI virtual machine, a lab server) runs other work beside the testbed. Three
neighbours stand for the usual kinds, each started before the run and stopped after it, each
niced (NICE), as a polite neighbour would be:

- `disk`: a writer that writes DISK_MB and syncs it, in a loop (dd with conv=fsync, niced);
- `churn`: another testbed's network of CHURN_ROBOTS robots brought up and torn down in a
  loop (`testbed net up` / `down`, niced: namespaces, veths, AODV daemons, their deletion).
  Its daemons' loops and kernel threads still take SCHED_RR 1, as every testbed's do (nice
  does not reach a real-time policy): the run's own daemons share their priority with them;
- `busy`: two niced busy loops, one a core.

`none` is the same run with no neighbour. The run is a lone robot of seed S at time scale 5
(the exactness test's runs, tests/integration/test_lone_exactness.py): exact means the same
steps and positions.csv as tests/data/lone-k5. The benchmark (`python -m testbed.bench
neighbours`) runs each neighbour RUNS times and writes results/bench/neighbours.json: per
neighbour, how many runs were exact and faithful, and the worst lateness of each kind of
process (the world's step loop, the robot's plans, plan timers and frame answers, each AODV
daemon's HELLO and expiry timers while the robots stepped, the robot's daemon and the
display's apart, the display's frames) with the host stalls the world saw; `worst` per
neighbour. TESTBED_NEIGHBOURS_KINDS, _SEEDS, _DAEMON and _NAME measure a part (`run`).
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

from aodv.statsfile import DaemonStats, StatsError, run_stats_path
from common.jsonfile import read_json
from testbed import PROJECT_ROOT
from testbed.bench.common import write
from testbed.run import fidelity
from testbed.run.results import display_summary

KINDS = ("none", "disk", "churn", "busy")
DISK_MB = 1500  # written and synced each round of the disk writer
CHURN_ROBOTS = 10
NICE = 10
TIME_SCALE = 5.0
DATA = os.path.join(PROJECT_ROOT, "tests", "data", "lone-k5")
STEPS = {1: 1901, 2: 1989, 3: 1964}  # a lone robot's steps at time scale 5 (the exactness test)
RUNS = 3
DAEMONS = ("auto", "cpp", "python")  # --aodv-daemon


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


def lone_run(seed: int, out: str, robot: str = "auto", aodv_daemon: str = "auto") -> dict:
    """A lone robot of `seed` at TIME_SCALE into `out` (`robot`, `aodv_daemon`: the run's
    --robot and --aodv-daemon): result.json's numbers that say how late each kind of process
    was, and whether the run was exact."""
    from testbed.run.execute import RunConfig, run
    from topology.network import destroy

    name = "nr" + uuid.uuid4().hex[:6]
    cfg = RunConfig(robots=1, comm_range=20.0, laser_range=2.0, seed=seed,
                    time_scale=TIME_SCALE, robot=robot, aodv_daemon=aodv_daemon)  # fmt: skip
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
    robot = (read_json(os.path.join(out, "robots", "r1.json")) or {}).get("lateness") or {}
    frames = (display_summary(out).get("lateness") or {}).get("frame_done_ms") or {}
    return {
        "seed": seed,
        "steps": r["steps"],
        "exact": r["steps"] == STEPS.get(seed) and same_path,
        "faithful": bool(r["fidelity"]["ok"]),
        "reason": r["fidelity"].get("reason"),
        "robot": r.get("robot"),
        "aodv_daemon": r.get("aodv_daemon"),
        "loadavg_1min": round(os.getloadavg()[0], 2),
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
            "plan_age_max_steps": m.get("plan_age_max_steps"),
            "late_timers": m.get("late_timers"),
            "timer_late_max_steps": m.get("timer_late_max_steps"),
            "frame_answer_max_ms": (robot.get("frame_answer_ms") or {}).get("max"),
            "late_dones": m.get("late_dones"),
        },
        "aodv": {
            "hello_late_max_ms": m.get("hello_late_max_ms"),
            "expiry_late_max_ms": m.get("expiry_late_max_ms"),
            **daemon_lateness(out),
        },  # fmt: skip
        "display": {"late_frames": m.get("display_late_frames"), "frame_max_ms": frames.get("max")},
    }


def stepping(out: str) -> tuple[float, float] | None:
    """CLOCK_MONOTONIC seconds of a run's first and last step (clock.csv), None without."""
    try:
        with open(os.path.join(out, "clock.csv")) as f:
            rows = [line.split(",") for line in f.read().splitlines()[1:] if line]
        return float(rows[0][1]), float(rows[-1][1])
    except (OSError, IndexError, ValueError):
        return None


def daemon_lateness(out: str) -> dict:
    """Each AODV daemon's worst HELLO and expiry lateness (emulated ms) while the robots
    stepped, as the fidelity verdict judges them (`robot_daemon`: the lone robot's, aodv/r1.json;
    `display_daemon`: the display's, aodv/r2.json); None for a daemon that left no statistics."""
    window = stepping(out)
    found: dict = {}
    for key, k in (("robot_daemon", 1), ("display_daemon", 2)):
        try:
            timers = DaemonStats.read(run_stats_path(out, k)).timer_lateness_ms
        except StatsError:
            timers = None
        if timers is None:
            found[key] = None
            continue
        one = fidelity.measures(None, [], daemons=[timers], stepping=window)
        found[key] = {"hello_ms": one.hello_late_max_ms, "expiry_ms": one.expiry_late_max_ms}
    return found


def _expected(seed: int) -> str | None:
    path = os.path.join(DATA, f"seed{seed}.positions.csv")
    if not os.path.exists(path):
        return None
    with open(path) as f:
        return f.read()


def measure(
    kinds: tuple[str, ...] = KINDS, seeds: tuple[int, ...] = (1, 2, 3), aodv_daemon: str = "auto"
) -> dict:
    out: dict = {"time_scale": TIME_SCALE, "loadavg_before": os.getloadavg(),
                 "aodv_daemon_asked": aodv_daemon, "neighbours": {}}  # fmt: skip
    for kind in kinds:
        runs = []
        for seed in seeds[:RUNS]:
            scratch = tempfile.mkdtemp(prefix="bench-nb-")
            try:
                with neighbour(kind, scratch):
                    runs.append(lone_run(seed, os.path.join(scratch, "run"),
                                         aodv_daemon=aodv_daemon))  # fmt: skip
            finally:
                shutil.rmtree(scratch, ignore_errors=True)
            print(f"  {kind} seed {seed}: {_line(runs[-1])}", flush=True)
        out["neighbours"][kind] = {
            "exact_and_faithful": sum(r["exact"] and r["faithful"] for r in runs),
            "runs": len(runs),
            "steps": [r["steps"] for r in runs],
            "hello_late_max_ms": max(r["aodv"]["hello_late_max_ms"] or 0 for r in runs),
            "late_plans": sum(r["robot_process"]["late_plans"] or 0 for r in runs),
            "host_stalled_s": round(sum(r["world"]["host_stalls"]["stalled_s"] for r in runs), 3),
            "worst": worst(runs),
            "each": runs,
        }
    return out


def worst(runs: list[dict]) -> dict:
    """The worst lateness of each kind of process over `runs` (summarise's dicts): the world's
    step (wall ms late), the robot's plans and plan timers (steps) and frame answers (emulated
    ms), each AODV daemon's HELLO and expiry timers and the display's frames (emulated ms)."""

    def most(values) -> float:
        return max((v for v in values if v is not None), default=0.0)

    def timer(key: str, kind: str) -> float:
        return most((r["aodv"].get(key) or {}).get(kind) for r in runs)

    return {
        "world_step_ms": most(r["world"]["worst_ms_late"] for r in runs),
        "robot_plan_age_steps": most(r["robot_process"]["plan_age_max_steps"] for r in runs),
        "robot_timer_late_steps": most(r["robot_process"]["timer_late_max_steps"] for r in runs),
        "robot_frame_answer_ms": most(r["robot_process"]["frame_answer_max_ms"] for r in runs),
        "robot_daemon_hello_ms": timer("robot_daemon", "hello_ms"),
        "robot_daemon_expiry_ms": timer("robot_daemon", "expiry_ms"),
        "display_daemon_hello_ms": timer("display_daemon", "hello_ms"),
        "display_daemon_expiry_ms": timer("display_daemon", "expiry_ms"),
        "display_frame_ms": most(r["display"]["frame_max_ms"] for r in runs),
    }


def _line(r: dict) -> str:
    """One run in a line: verdict, steps, the daemons' worst HELLO lateness."""
    verdict = ("exact" if r["exact"] else "NOT exact") + (
        ", faithful" if r["faithful"] else f", NOT faithful ({r['reason']})"
    )
    hello = [
        (r["aodv"].get(k) or {}).get("hello_ms") for k in ("robot_daemon", "display_daemon")
    ]  # fmt: skip
    return (f"{r['steps']} steps, {verdict}; HELLO late (ms) robot's daemon {hello[0]}, "
            f"display's {hello[1]}; load {r['loadavg_1min']}")  # fmt: skip


def _env_list(name: str, default: tuple, known: tuple) -> tuple:
    """A comma-separated choice among `known` from the environment; one line and exit 2 when
    it names anything else."""
    text = os.environ.get(name)
    if text is None:
        return default
    asked = tuple(x.strip() for x in text.split(",") if x.strip())
    names = [str(k) for k in known]
    if not asked or not set(asked) <= set(names):
        print(f"bench neighbours: {name}={text[:40]!r}: a comma-separated list of "
              f"{', '.join(names)}", file=sys.stderr)  # fmt: skip
        sys.exit(2)
    return tuple(known[names.index(a)] for a in asked)


def run() -> None:
    """`python -m testbed.bench neighbours`; TESTBED_NEIGHBOURS_KINDS (e.g. "disk,busy") and
    TESTBED_NEIGHBOURS_SEEDS (e.g. "2,3") choose fewer, TESTBED_NEIGHBOURS_NAME another file
    name than neighbours (results/bench/NAME.json), so that a measurement in parts keeps each;
    TESTBED_NEIGHBOURS_DAEMON (auto, cpp or python) the AODV daemon, for a comparison."""
    kinds = _env_list("TESTBED_NEIGHBOURS_KINDS", KINDS, KINDS)
    seeds = _env_list("TESTBED_NEIGHBOURS_SEEDS", tuple(STEPS), tuple(STEPS))
    daemon = os.environ.get("TESTBED_NEIGHBOURS_DAEMON", "auto")
    if daemon not in DAEMONS:
        print(f"bench neighbours: TESTBED_NEIGHBOURS_DAEMON={daemon[:40]!r}: one of "
              f"{', '.join(DAEMONS)}", file=sys.stderr)  # fmt: skip
        sys.exit(2)
    name = os.environ.get("TESTBED_NEIGHBOURS_NAME", "neighbours")
    if not (name.replace("-", "").replace("_", "").isalnum() and name.isascii()):
        print(f"bench neighbours: TESTBED_NEIGHBOURS_NAME={name[:40]!r}: letters, digits, - "
              "and _ only", file=sys.stderr)  # fmt: skip
        sys.exit(2)
    result = measure(kinds, seeds, daemon)
    print(f"bench neighbours: {write(name, result)}")
    print(json.dumps({k: {x: v[x] for x in v if x != "each"}
                      for k, v in result["neighbours"].items()}, indent=1))  # fmt: skip
