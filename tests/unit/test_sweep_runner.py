"""The sweep runner end to end with a stand-in for `testbed run`.

The stand-in is a real program that parses the flags the sweep passes, writes config.json
first and result.json last (atomically), as docs/run-results.md says `testbed run` does, and
stops on SIGINT/SIGTERM without a result. With it the sweep's process handling (concurrency,
interrupt, resume, back-off, failures) is exercised for real, without namespaces. The same
scenarios against the real `testbed run` are in tests/integration/test_sweep_short.py.
"""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]

STANDIN = r"""
import argparse, json, os, signal, sys, time
p = argparse.ArgumentParser()
for f in ("--robots", "--seed", "--max-steps"):
    p.add_argument(f, type=int)
for f in ("--comm-range", "--laser-range", "--time-scale", "--loss", "--delay"):
    p.add_argument(f, type=float, default=0.0)
p.add_argument("--routing"); p.add_argument("--map"); p.add_argument("--out")
p.add_argument("--coordination"); p.add_argument("--start")
p.add_argument("--capture", action="store_true"); p.add_argument("--quiet", action="store_true")
p.add_argument("--view"); p.add_argument("--steps-over")
p.add_argument("--start-when"); p.add_argument("--start-timeout", type=float)
a = p.parse_args()
signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
t_start = t_proc = time.monotonic()
pids = os.environ.get("STANDIN_PIDS")
if pids:
    with open(os.path.join(pids, str(os.getpid())), "w") as f:
        f.write(a.out)
if str(a.robots) in os.environ.get("STANDIN_FAIL", "").split(","):
    print("standin: failing on purpose", file=sys.stderr)
    sys.exit(3)
os.makedirs(a.out)
cfg = {"robots": a.robots, "comm_range": a.comm_range, "laser_range": a.laser_range,
       "seed": a.seed, "time_scale": a.time_scale, "routing": a.routing, "map": a.map,
       "loss_pct": a.loss, "delay_ms": a.delay, "capture": a.capture,
       "max_steps": a.max_steps, "coordination": a.coordination, "start": a.start}
with open(os.path.join(a.out, "config.json"), "w") as f:
    json.dump(cfg, f)
gate_wait = None
if a.start_when:  # pre-started: set up (config.json), then wait for the gate
    shut = os.path.basename(a.out) in os.environ.get("STANDIN_GATE_SHUT_IDS", "").split(",")
    once = os.path.join(os.path.dirname(a.steps_over or a.out), "gate-shut-" +
                        os.path.basename(a.out))
    if shut and not os.path.exists(once):  # its gate stays shut (once): as if it timed out
        open(once, "x").close()
        res = {"format": 1, "config": cfg, "status": "gate_timeout",
               "status_detail": f"the start gate {a.start_when} stayed shut for "
                                f"{a.start_timeout:g} s", "steps": 0}
        with open(os.path.join(a.out, "result.json"), "w") as f:
            json.dump(res, f)
        sys.exit(1)
    while not os.path.exists(a.start_when):
        if time.monotonic() - t_proc > a.start_timeout:
            sys.exit(4)
        time.sleep(0.002)
    t_start = time.monotonic()  # its steps start here
    gate_wait = round(t_start - t_proc, 3)
if a.view:
    with open(os.path.join(a.out, "view.txt"), "w") as f:
        f.write(f"{a.view} {time.monotonic()}")
time.sleep(float(os.environ.get("STANDIN_SLEEP", "0.05")))
miss = float(os.environ.get("STANDIN_MISS", "0")) if str(a.robots) in os.environ.get(
    "STANDIN_MISS_ROBOTS", "").split(",") or os.path.basename(a.out) in os.environ.get(
    "STANDIN_MISS_IDS", "").split(",") else 0.0
robots = {f"r{k}": {"finish_step": 100 + k, "crashed": False, "exit_status": 0,
                    "plans": [{"step": 0, "cause": "start"}, {"step": 20, "cause": "timer"}],
                    "messages": {"sent": {}, "received": {}}, "path_length_m": 1.0}
          for k in range(1, a.robots + 1)}
ours = float(os.environ.get("STANDIN_MISS_OURS", miss))  # outside host stalls
res = {"format": 1, "config": cfg, "status": "complete", "status_detail": "", "steps": 120,
       "coverage_final": 0.99, "time_scale_requested": a.time_scale,
       "time_scale_achieved": a.time_scale, "deadlines_missed": 0,
       "deadline_miss_fraction": miss, "deadline_miss_fraction_outside_stalls": min(miss, ours),
       "wall_time_s": 0.2, "robots": robots}
above = os.environ.get("STANDIN_UNFAITHFUL_ABOVE")  # time scales above it are not faithful
if above and a.time_scale > float(above):
    res["fidelity"] = {"ok": False, "reason": "12 of 30 plans applied a step or more late "
                                              "(40.0%, limit 1.0%)"}
elif above:
    res["fidelity"] = {"ok": True}
per_load = os.environ.get("STANDIN_CORES_PER_LOAD")  # the CPU it says it used while stepping
if per_load:
    wall = float(os.environ.get("STANDIN_SLEEP", "0.05"))
    cores = float(per_load) * (a.robots + 1) * a.time_scale
    res["cpu_s"] = {"robots": cores * wall, "display": 0.0, "world": 0.0, "routing": 0.0}
    res["wall_parts_s"] = {"steps": wall}
if gate_wait is not None:
    res["wall_parts_s"] = dict(res.get("wall_parts_s", {}), gate_wait=gate_wait)
t_steps = time.monotonic()
tail = os.environ.get("STANDIN_TAIL")  # seconds of teardown after its steps
if tail and a.steps_over:
    open(a.steps_over, "x").close()
    time.sleep(float(tail))
tmp = os.path.join(a.out, "result.json.tmp")
with open(tmp, "w") as f:
    json.dump(res, f)
os.replace(tmp, os.path.join(a.out, "result.json"))
times = os.environ.get("STANDIN_TIMES")
if times:
    with open(os.path.join(times, str(os.getpid())), "w") as f:
        f.write(f"{t_start} {time.monotonic()} {a.robots} {a.time_scale} {t_steps} {t_proc}")
"""

SWEEP = """
[grid]
robots = [1, 2, 3]
comm_range = [5, 20]
laser_range = [2.0]
runs = 1

[run]
time_scale = 5
max_steps = 500
"""


@pytest.fixture
def env(tmp_path):
    standin = tmp_path / "standin.py"
    standin.write_text(STANDIN)
    sweep_file = tmp_path / "s.toml"
    sweep_file.write_text(SWEEP)
    pids = tmp_path / "pids"
    pids.mkdir()
    e = dict(os.environ)
    e["TESTBED_SWEEP_RUN_COMMAND"] = f"{sys.executable} {standin}"
    e["STANDIN_PIDS"] = str(pids)
    e["PYTHONPATH"] = str(REPO)
    return {"env": e, "file": sweep_file, "tmp": tmp_path, "pids": pids}


def sweep_argv(env, out, *extra):
    return [
        sys.executable,
        "-m",
        "testbed.sweep.command",
        str(env["file"]),
        "--out",
        str(out),
        *extra,
    ]


def run_sweep(env, out, *extra, **env_over):
    """The sweep to its end. One CI run saw a sweep stop making progress (2 of 6 runs done
    after 10 s, then nothing for 110 s), not seen again in 17 repeats of that test: should it
    come back, the failure shows where the sweep was (faulthandler's stacks on SIGABRT) and
    which stand-ins had started."""
    e = dict(env["env"], **env_over)
    argv = [sys.executable, "-X", "faulthandler", *sweep_argv(env, out, *extra)[1:]]
    p = subprocess.Popen(argv, env=e, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True)  # fmt: skip
    try:
        stdout, stderr = p.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        p.send_signal(signal.SIGABRT)
        stdout, stderr = p.communicate()
        started = sorted(os.listdir(env["pids"]))
        pytest.fail(f"sweep still running after 120 s; stand-ins started: {started}\n{stderr}")
    return subprocess.CompletedProcess(argv, p.returncode, stdout, stderr)


def results(out: Path) -> dict:
    """run id -> result.json content, for every complete run."""
    return {p.parent.name: json.loads(p.read_text()) for p in out.glob("runs/*/result.json")}


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # a zombie is dead for our purpose
    try:
        return Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"
    except OSError:
        return False


def test_full_sweep_passes_the_config_through(env):
    out = env["tmp"] / "out"
    r = run_sweep(env, out, "--jobs", "2")
    assert r.returncode == 0, r.stderr
    res = results(out)
    assert len(res) == 6
    state = json.loads((out / "sweep.json").read_text())
    assert {x["status"] for x in state["runs"]} == {"done"}
    for entry in state["runs"]:
        # what the stand-in parsed from the command line is exactly the planned config
        assert res[entry["id"]]["config"] == entry["config"]
    assert "6/6 done" in r.stderr


def test_existing_directory_needs_resume(env):
    out = env["tmp"] / "out"
    assert run_sweep(env, out).returncode == 0
    r = run_sweep(env, out)
    assert r.returncode == 2
    assert r.stderr.strip().splitlines()[-1].count("--resume") == 1
    before = {k: (out / "runs" / k / "result.json").stat().st_mtime_ns for k in results(out)}
    r = run_sweep(env, out, "--resume")
    assert r.returncode == 0 and "6 done, 0 to do" in r.stderr
    after = {k: (out / "runs" / k / "result.json").stat().st_mtime_ns for k in results(out)}
    assert before == after  # nothing redone


def interrupted_then_resumed(env, sig):
    reference = env["tmp"] / "reference"
    assert run_sweep(env, reference, "--jobs", "2").returncode == 0
    out = env["tmp"] / "out"
    e = dict(env["env"], STANDIN_SLEEP="1.0")
    p = subprocess.Popen(
        sweep_argv(env, out, "--jobs", "2"), env=e, cwd=REPO, stderr=subprocess.PIPE, text=True
    )
    # wait until two runs are done and two more in flight
    deadline = time.monotonic() + 30
    while len(results(out)) < 2 and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.3)
    p.send_signal(sig)
    p.wait(timeout=60)
    done_at_stop = set(results(out))
    assert 2 <= len(done_at_stop) < 6
    # every run process the sweep started is gone (SIGINT: stopped; SIGKILL: PDEATHSIG)
    pids = [int(x.name) for x in env["pids"].iterdir()]
    deadline = time.monotonic() + 10
    while any(alive(pid) for pid in pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not any(alive(pid) for pid in pids)
    r = run_sweep(env, out, "--resume", "--jobs", "2")
    assert r.returncode == 0, r.stderr
    final = results(out)
    ref = results(reference)
    assert set(final) == set(ref)
    assert {k: v["config"] for k, v in final.items()} == {k: v["config"] for k, v in ref.items()}
    return p, done_at_stop, r


def test_sigint_then_resume(env):
    p, done_at_stop, r = interrupted_then_resumed(env, signal.SIGINT)
    assert p.returncode == 130
    assert "resume with --resume" in p.stderr.read()
    assert f"{len(done_at_stop)} done" in r.stderr


def test_sigkill_then_resume(env):
    p, done_at_stop, r = interrupted_then_resumed(env, signal.SIGKILL)
    assert p.returncode == -signal.SIGKILL
    assert f"{len(done_at_stop)} done" in r.stderr


def test_backs_off_when_runs_miss_deadlines(env):
    out = env["tmp"] / "out"
    r = run_sweep(env, out, "--jobs", "2", STANDIN_MISS="0.05", STANDIN_MISS_ROBOTS="2")
    assert r.returncode == 0, r.stderr
    state = json.loads((out / "sweep.json").read_text())
    assert state["jobs_requested"] == 2 and state["jobs"] == 1
    assert state["backoffs"] and state["backoffs"][0]["deadline_miss_fraction"] == 0.05
    assert "concurrency down to 1" in r.stderr
    assert len(results(out)) == 6


def test_failed_runs_are_reported_and_retried_on_resume(env):
    out = env["tmp"] / "out"
    r = run_sweep(env, out, STANDIN_FAIL="2")
    assert r.returncode == 1
    assert "2 failed run(s)" in r.stderr
    state = json.loads((out / "sweep.json").read_text())
    failed = [x for x in state["runs"] if x["status"] == "failed"]
    assert {x["config"]["robots"] for x in failed} == {2}
    assert all("failing on purpose" in x["reason"] for x in failed)
    r = run_sweep(env, out, "--resume")
    assert r.returncode == 0 and len(results(out)) == 6


def test_load_limit_packs_small_teams_and_never_overloads(env):
    """Per-team time scales and a load limit: runs share the machine only while the sum of
    their loads, (robots + 1) x time_scale, stays within the limit."""
    env["file"].write_text(
        SWEEP.replace("time_scale = 5", "time_scale = { 1 = 10, 2 = 8, 3 = 6 }\nload_limit = 45")
    )
    times = env["tmp"] / "times"
    times.mkdir()
    out = env["tmp"] / "out"
    r = run_sweep(env, out, "--jobs", "3", STANDIN_SLEEP="0.6", STANDIN_TIMES=str(times))
    assert r.returncode == 0, r.stderr
    spans = [tuple(float(v) for v in p.read_text().split()[:4]) for p in times.iterdir()]
    assert sorted((int(n), ts) for _, _, n, ts in spans) == [(1, 10), (1, 10), (2, 8), (2, 8),
                                                            (3, 6), (3, 6)]  # fmt: skip
    overlapped = False
    for t0, _, _, _ in spans:  # the load in flight whenever a run started
        now = [(n + 1) * ts for s0, s1, n, ts in spans if s0 <= t0 < s1]
        assert sum(now) <= 45
        overlapped |= len(now) > 1
    assert overlapped  # the small teams did share the machine
    state = json.loads((out / "sweep.json").read_text())
    assert state["load_limit"] == 45 and state["spec"]["time_scale_by_robots"]["3"] == 6


def lone_robots(env, comm, cpu_limit=1.0):
    """lone_robot_sweep (time scale 5: a load of 10 each) under a cpu limit."""
    packed = lone_robot_sweep(env, comm)
    packed["file"].write_text(packed["file"].read_text() + f"cpu_limit = {cpu_limit}\n")
    return packed


def spans_by_run(env, times: Path) -> dict[str, tuple[float, float]]:
    """run id -> (start, end) of every stand-in that ran to its end (STANDIN_PIDS says which
    run a process made)."""
    out = {}
    for p in times.iterdir():
        t0, t1, *_ = p.read_text().split()
        rid = Path((env["pids"] / p.name).read_text()).name
        out[rid] = (float(t0), float(t1))
    return out


def packed_sweep(env, cpu_limit: float, *extra):
    """Six lone robots at scale 5 (a load of 10) that measure 0.04 cores per unit of load,
    0.4 cores each, under `cpu_limit`: (the result, sweep.json, each run's span and its
    estimated cores)."""
    times = env["tmp"] / "times"
    times.mkdir()
    out = env["tmp"] / "out"
    r = run_sweep(lone_robots(env, comm=(5, 10, 15, 20, 25, 30), cpu_limit=cpu_limit), out,
                  *extra, STANDIN_SLEEP="0.5", STANDIN_TIMES=str(times),
                  STANDIN_CORES_PER_LOAD="0.04")  # fmt: skip
    assert r.returncode == 0, r.stderr
    state = json.loads((out / "sweep.json").read_text())
    estimated = {e["id"]: e["cores_estimated"] for e in state["runs"]}
    spans = [(t0, t1, estimated[rid]) for rid, (t0, t1) in spans_by_run(env, times).items()]
    assert len(spans) == 6
    return r, state, spans


def most_in_flight(spans) -> tuple[int, float]:
    """The most runs, and the most estimated cores, in flight when a run started."""
    runs, cores = 0, 0.0
    for t0, _, _ in spans:
        now = [c for s0, s1, c in spans if s0 <= t0 < s1]
        runs, cores = max(runs, len(now)), max(cores, sum(now))
    return runs, cores


def test_cpu_limit_packs_runs_by_their_estimated_cores(env):
    """Under a cpu limit of 1.0: first at the prior's estimate (0.225 cores each), then, once
    a run has measured 0.4, two at a time; never more estimated cores in flight than that."""
    r, state, spans = packed_sweep(env, 1.0, "--jobs", "4")
    assert "up to 4 at a time within 1 core (cpu_limit)" in r.stderr
    assert state["cpu_limit_requested"] == state["cpu_limit"] == 1.0
    assert {e["cores_measured"] for e in state["runs"]} == {0.4}
    estimated = sorted(e["cores_estimated"] for e in state["runs"])
    assert estimated[0] == pytest.approx(0.225) and estimated[-1] == 0.4
    runs, cores = most_in_flight(spans)
    assert runs > 1 and cores <= 1.0 + 1e-9


def test_cpu_limit_keeps_runs_apart_when_two_do_not_fit(env):
    """A limit under two runs' estimate (0.45 at the prior, 0.8 measured): one at a time,
    though four jobs are allowed."""
    _, state, spans = packed_sweep(env, 0.4, "--jobs", "4")
    assert most_in_flight(spans)[0] == 1
    assert state["cpu_limit"] == 0.4 and not state["backoffs"]


def test_cpu_limit_is_capped_by_an_explicit_jobs(env):
    assert most_in_flight(packed_sweep(env, 2.0, "--jobs", "1")[2])[0] == 1


def test_a_shared_run_late_under_a_cpu_limit_lowers_it_and_is_redone(env):
    out = env["tmp"] / "out"
    r = run_sweep(lone_robots(env, comm=(5, 10)), out, "--jobs", "2", STANDIN_SLEEP="0.3",
                  STANDIN_CORES_PER_LOAD="0.04", STANDIN_MISS="0.05",
                  STANDIN_MISS_IDS="n01-c5-l2-k1")  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "cpu limit down to 0.36 cores, redoing it" in r.stderr  # 80% of 2 x 0.225
    state = json.loads((out / "sweep.json").read_text())
    assert state["cpu_limit_requested"] == 1.0 and state["cpu_limit"] <= 0.36
    assert state["backoffs"][0] == {"run": "n01-c5-l2-k1", "deadline_miss_fraction": 0.05,
                                    "cpu_limit": 0.36}  # fmt: skip
    assert {e["id"]: e["attempts"] for e in state["runs"]}["n01-c5-l2-k1"] == 2
    # The redo (0.4 cores measured) does not fit beside the other run under 0.36: it ran
    # alone, late again, and that is the team's time scale (rule 6), not the limit.
    assert [set(b) - {"run", "deadline_miss_fraction"} for b in state["backoffs"]] == [
        {"cpu_limit"}, {"robots", "time_scale_factor"}]  # fmt: skip


def test_a_run_late_alone_slows_the_sweep_down(env):
    """One run at a time, and runs of 2 robots miss deadlines: the machine is slower than the
    file assumes, so the time scales go down; a run that missed over 5% is redone (at most
    twice), one that missed less is kept."""
    out = env["tmp"] / "out"
    r = run_sweep(
        env, out, "--jobs", "1", "--no-prestart", STANDIN_MISS="0.08", STANDIN_MISS_ROBOTS="2"
    )
    assert r.returncode == 0, r.stderr
    assert "time scales of teams of 2 down to 85% of the file's" in r.stderr
    state = json.loads((out / "sweep.json").read_text())
    factors = state["time_scale_factor"]
    assert "1" not in factors and "3" not in factors  # other team sizes keep their scale
    assert factors["2"] == pytest.approx(0.85**6, abs=1e-3)  # 2 runs x 3
    attempts = {x["id"]: x["attempts"] for x in state["runs"]}
    assert attempts["n02-c5-l2-k1"] == 3 and attempts["n01-c5-l2-k1"] == 1
    res = results(out)
    assert res["n01-c5-l2-k1"]["config"]["time_scale"] == 5  # before the first miss
    assert res["n02-c5-l2-k1"]["config"]["time_scale"] == pytest.approx(5 * 0.85**2, abs=0.01)
    assert res["n02-c20-l2-k1"]["config"]["time_scale"] == pytest.approx(5 * 0.85**5, abs=0.01)
    assert res["n03-c20-l2-k1"]["config"]["time_scale"] == 5
    r = run_sweep(env, out, "--resume", "--jobs", "1")  # slower runs still count as done
    assert r.returncode == 0 and "6 done" in r.stderr, r.stderr


def test_a_run_a_little_late_is_kept(env):
    out = env["tmp"] / "out"
    r = run_sweep(
        env, out, "--jobs", "1", "--no-prestart", STANDIN_MISS="0.02", STANDIN_MISS_ROBOTS="2"
    )
    assert r.returncode == 0, r.stderr
    state = json.loads((out / "sweep.json").read_text())
    assert all(x["attempts"] == 1 for x in state["runs"])
    assert state["time_scale_factor"]["2"] == pytest.approx(0.85**2, abs=1e-3)


def test_a_team_size_speeds_up_again_after_clean_runs(env):
    """A burst on the host: one run of a lone robot misses 2% and the lone robot's later runs
    go at 85%; three clean runs later they are back at the file's scale."""
    sweep_file = env["tmp"] / "ones.toml"
    sweep_file.write_text(SWEEP.replace("robots = [1, 2, 3]", "robots = [1]").replace(
        "comm_range = [5, 20]", "comm_range = [5, 10, 15, 20, 25]"))  # fmt: skip
    out = env["tmp"] / "out"
    r = run_sweep(dict(env, file=sweep_file), out, "--jobs", "1", "--no-prestart",
                  STANDIN_MISS="0.02", STANDIN_MISS_IDS="n01-c5-l2-k1")  # fmt: skip
    assert r.returncode == 0, r.stderr
    scales = {rid: res["config"]["time_scale"] for rid, res in results(out).items()}
    assert scales["n01-c5-l2-k1"] == 5
    assert [scales[f"n01-c{c}-l2-k1"] for c in (10, 15, 20)] == [4.25] * 3
    assert scales["n01-c25-l2-k1"] == 5
    state = json.loads((out / "sweep.json").read_text())
    assert state["time_scale_factor"]["1"] == pytest.approx(1.0)
    assert "time scales of teams of 1 up to 100%" in r.stderr


def test_misses_in_host_stalls_do_not_slow_the_sweep_down(env):
    """Runs of 2 robots miss 8% of their deadlines, all but 0.2% while the host stalled the
    machine: no time scale changes; each is redone as it was (at most twice), then kept."""
    out = env["tmp"] / "out"
    r = run_sweep(env, out, "--jobs", "1", "--no-prestart", STANDIN_MISS="0.08",
                  STANDIN_MISS_ROBOTS="2", STANDIN_MISS_OURS="0.002")  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "(7.8% in host stalls); the host's stalls, time scale kept, redoing it" in r.stderr
    state = json.loads((out / "sweep.json").read_text())
    assert state["time_scale_factor"] == {}
    attempts = {x["id"]: x["attempts"] for x in state["runs"]}
    assert attempts["n02-c5-l2-k1"] == 3 and attempts["n01-c5-l2-k1"] == 1
    assert {res["config"]["time_scale"] for res in results(out).values()} == {5}


def test_calibrate_finds_each_team_sizes_scale_and_runs_there(env, tmp_path):
    out = tmp_path / "cal"
    # Team 1's third trial misses 2%: its factor stops at the second (1/0.85 of the file's);
    # team 2 misses at the file's scale and goes down until clean; team 3 is clean up to 4x.
    r = run_sweep(env, out, "--calibrate", STANDIN_MISS="0.02",
                  STANDIN_MISS_IDS="n01-3,n02-1,n02-2")  # fmt: skip
    assert r.returncode == 0, r.stderr
    cal = json.loads((out / "sweep.json").read_text())["calibration"]
    assert [f for f, *_ in cal["1"]["trials"]] == [1.0, 1.176, 1.384]
    assert cal["1"]["factor"] == 1.176
    assert [f for f, *_ in cal["2"]["trials"]] == [1.0, 0.85, 0.722]
    assert cal["2"]["factor"] == 0.722
    assert cal["3"]["factor"] == 4.0
    scales = {d["config"]["robots"]: d["config"]["time_scale"] for d in results(out).values()}
    assert scales == {1: round(5 * 1.176, 3), 2: round(5 * 0.722, 3), 3: 20.0}
    assert all(p.name.startswith("n0") for p in (out / "calibration").iterdir())


def lone_robot_sweep(env, comm=(5, 20)):
    sweep_file = env["tmp"] / "ones.toml"
    sweep_file.write_text(SWEEP.replace("robots = [1, 2, 3]", "robots = [1]").replace(
        "comm_range = [5, 20]", f"comm_range = {list(comm)}"))  # fmt: skip
    return dict(env, file=sweep_file)


def test_an_unfaithful_run_is_redone_once_at_a_lower_scale(env):
    """The lone robot's first run, at the file's scale 5, is in time but not faithful: its
    team size goes down to 85% and the run is redone there (faithful); the next run too."""
    out = env["tmp"] / "out"
    r = run_sweep(
        lone_robot_sweep(env), out, "--jobs", "1", "--no-prestart", STANDIN_UNFAITHFUL_ABOVE="4.5"
    )
    assert r.returncode == 0, r.stderr
    assert (
        "not faithful (12 of 30 plans applied a step or more late (40.0%, limit 1.0%))" in r.stderr
    )
    assert "time scales of teams of 1 down to 85% of the file's, redoing it" in r.stderr
    state = json.loads((out / "sweep.json").read_text())
    attempts = {x["id"]: x["attempts"] for x in state["runs"]}
    assert attempts == {"n01-c5-l2-k1": 2, "n01-c20-l2-k1": 1}
    assert state["backoffs"][0]["faithful"] is False
    assert {res["config"]["time_scale"] for res in results(out).values()} == {4.25}
    assert all(res["fidelity"]["ok"] for res in results(out).values())


def test_calibrate_climbs_only_while_its_trials_are_faithful(env, tmp_path):
    out = tmp_path / "cal"
    r = run_sweep(lone_robot_sweep(env, comm=(20,)), out, "--calibrate",
                  STANDIN_UNFAITHFUL_ABOVE="6.5")  # fmt: skip
    assert r.returncode == 0, r.stderr
    cal = json.loads((out / "sweep.json").read_text())["calibration"]["1"]
    assert cal["trials"] == [[1.0, 0.0, True], [1.176, 0.0, True], [1.384, 0.0, False]]
    assert cal["factor"] == 1.176
    assert [res["config"]["time_scale"] for res in results(out).values()] == [5.88]


def test_jobs_auto_is_one_at_a_time_on_two_cores_and_more_on_big_machines():
    from testbed.sweep import file as sweepfile
    from testbed.sweep import plan as sweepplan

    runs = sweepfile.expand(sweepfile.load(REPO / "testbed" / "experiments" / "paper.toml"))
    assert sweepplan.auto_jobs(runs, cores=2) == 1
    assert sweepplan.auto_jobs(runs, cores=64) >= 8  # ten robots at K = 20: 6 CPUs a run


def test_report_says_which_scales_each_team_ran_at(env, tmp_path):
    from testbed.analysis import report

    out = tmp_path / "cal2"
    r = run_sweep(env, out, "--calibrate", STANDIN_MISS="0.02", STANDIN_MISS_IDS="n01-2")
    assert r.returncode == 0, r.stderr
    path, _ = report.write_report(out, metrics_of=lambda run: None)
    text = path.read_text()
    assert "Time scales the runs ran at, per team size: 1: 5 (2 runs)" in text
    assert "Calibrated on this machine" in text and "1 robots x1 of the file's scale" in text


def test_view_goes_to_one_run_at_a_time(env, tmp_path):
    out = tmp_path / "view"
    times = tmp_path / "times"
    times.mkdir()
    r = run_sweep(env, out, "--jobs", "2", "--view", "127.0.0.1:9999", STANDIN_SLEEP="0.3",
                  STANDIN_TIMES=str(times))  # fmt: skip
    assert r.returncode == 0, r.stderr
    viewed = sorted(p.parent.name for p in out.glob("runs/*/view.txt"))
    assert viewed and all((out / "runs" / v / "view.txt").read_text().startswith("127.0.0.1:9999")
                          for v in viewed)  # fmt: skip
    spans = {}
    for f in times.iterdir():
        t0, t1, robots, *_ = f.read_text().split()
        spans[f.name] = (float(t0), float(t1))
    # Runs ran two at a time, yet the view was never handed to two at once: count overlaps.
    view_starts = sorted(float((out / "runs" / v / "view.txt").read_text().split()[1])
                         for v in viewed)  # fmt: skip
    assert len(view_starts) < len(spans)  # not every run got it (the other one was running)


def tail_spans(env, times: Path) -> list[tuple[float, float, float]]:
    """(start, steps done, end) of every stand-in that ran to its end, by start."""
    spans = []
    for p in times.iterdir():
        t0, t1, _, _, ts, _ = p.read_text().split()
        spans.append((float(t0), float(ts), float(t1)))
    return sorted(spans)


def test_the_next_run_starts_during_the_tail_of_the_last(env):
    """One run at a time, each with 0.4 s of tail after its steps: the next run starts once
    the last one said its steps were done, before it exits, and no two runs step at once;
    the steps-over files are gone at the end."""
    times = env["tmp"] / "times"
    times.mkdir()
    out = env["tmp"] / "out"
    r = run_sweep(env, out, "--jobs", "1", "--no-prestart", STANDIN_SLEEP="0.2", STANDIN_TAIL="0.4",
                  STANDIN_TIMES=str(times))  # fmt: skip
    assert r.returncode == 0, r.stderr
    spans = tail_spans(env, times)
    assert len(spans) == 6
    for (_, steps_done, end), (start, next_steps_done, _) in zip(spans, spans[1:], strict=False):
        assert steps_done <= start < end  # in the tail: overlapped
        assert next_steps_done > steps_done
    for i, (t0, ts, _) in enumerate(spans):  # no two runs' steps at once
        assert all(ts <= s0 or s1 <= t0 for j, (s0, s1, _) in enumerate(spans) if j != i)
    assert not list((out / "logs").glob("*.steps-over"))
    state = json.loads((out / "sweep.json").read_text())
    assert not state["backoffs"]
    assert [e.get("overlapped", False) for e in state["runs"]] == [False] + [True] * 5


def test_a_run_late_beside_a_tail_turns_the_overlap_off_for_its_team_size(env):
    """A lone robot's run that missed deadlines while another's tail went on: lone robots
    give up the overlap (rule 3) and the run is redone after every run before it exited,
    while teams of 2 and 3 still start during the tail before them."""
    times = env["tmp"] / "times"
    times.mkdir()
    out = env["tmp"] / "out"
    r = run_sweep(env, out, "--jobs", "1", "--no-prestart", STANDIN_SLEEP="0.2", STANDIN_TAIL="0.4",
                  STANDIN_TIMES=str(times), STANDIN_MISS="0.05",
                  STANDIN_MISS_IDS="n01-c20-l2-k1")  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "teams of 1 no longer start during another run's teardown, redoing it" in r.stderr
    state = json.loads((out / "sweep.json").read_text())
    assert state["backoffs"][0] == {"run": "n01-c20-l2-k1", "deadline_miss_fraction": 0.05,
                                    "robots": 1, "overlap": False}  # fmt: skip
    spans = tail_spans(env, times)
    assert len(spans) == 7  # the late run twice
    lone = sorted(p for p in times.iterdir() if p.read_text().split()[2] == "1")
    assert len(lone) == 3
    redo = max(float(p.read_text().split()[0]) for p in lone)  # the last lone start
    assert all(end <= redo for t0, _, end in spans if t0 < redo)  # waited for every tail
    later = [sp for sp in spans if sp[0] > redo]
    assert later and any(prev[1] <= nxt[0] < prev[2] for prev, nxt in
                         zip(spans, spans[1:], strict=False) if nxt[0] > redo)  # fmt: skip


def prestart_spans(times: Path) -> list[tuple[float, float, float, float]]:
    """(process start, steps start, steps done, end) of every stand-in that ran to its end,
    by steps start."""
    spans = []
    for p in times.iterdir():
        t0, t1, _, _, ts, tp = p.read_text().split()
        spans.append((float(tp), float(t0), float(ts), float(t1)))
    return sorted(spans, key=lambda s: s[1])


def test_the_next_run_is_prestarted_while_the_last_one_steps(env):
    """One run at a time: each run after the first starts (sets up) while the one before it
    steps, and its steps start only once that one's are done (its gate); no two runs step
    at once, the waits are recorded (result.json's wall_parts_s.gate_wait, sweep.json's
    gate_wait_s), and no gate or steps-over file is left."""
    times = env["tmp"] / "times"
    times.mkdir()
    out = env["tmp"] / "out"
    r = run_sweep(env, out, "--jobs", "1", STANDIN_SLEEP="0.4", STANDIN_TAIL="0.2",
                  STANDIN_TIMES=str(times))  # fmt: skip
    assert r.returncode == 0, r.stderr
    spans = prestart_spans(times)
    assert len(spans) == 6
    for prev, nxt in zip(spans, spans[1:], strict=False):
        assert nxt[0] < prev[2]  # set up while the one before stepped
        assert prev[2] <= nxt[1]  # its steps after that one's
    state = json.loads((out / "sweep.json").read_text())
    runs = state["runs"]
    prestarted = [e for e in runs if e.get("prestarted")]
    assert len(prestarted) == 5 and all(e["gate_wait_s"] > 0 for e in prestarted)
    assert sum(bool(e.get("prestarted_beside")) for e in runs) == 5
    assert not list((out / "logs").glob("*.gate")) and not list((out / "logs").glob("*.steps-over"))
    assert not state["backoffs"]


def test_no_prestart_starts_each_run_when_it_may_step(env):
    """--no-prestart: no run starts before the steps of the one before it are done."""
    times = env["tmp"] / "times"
    times.mkdir()
    out = env["tmp"] / "out"
    r = run_sweep(env, out, "--jobs", "1", "--no-prestart", STANDIN_SLEEP="0.3",
                  STANDIN_TAIL="0.2", STANDIN_TIMES=str(times))  # fmt: skip
    assert r.returncode == 0, r.stderr
    spans = prestart_spans(times)
    assert len(spans) == 6
    assert all(prev[2] <= nxt[0] for prev, nxt in zip(spans, spans[1:], strict=False))
    state = json.loads((out / "sweep.json").read_text())
    assert not any(e.get("prestarted") or e.get("prestarted_beside") for e in state["runs"])


def test_a_run_late_beside_a_prestart_turns_prestart_off_beside_its_team_size(env):
    """A lone robot's run that missed deadlines while the next run pre-started beside it:
    no run is pre-started beside lone robots any more (rule 3a) and the run is redone; the
    run after the redo set up only once the redo's steps were done."""
    times = env["tmp"] / "times"
    times.mkdir()
    out = env["tmp"] / "out"
    r = run_sweep(env, out, "--jobs", "1", STANDIN_SLEEP="0.3", STANDIN_TIMES=str(times),
                  STANDIN_MISS="0.05", STANDIN_MISS_IDS="n01-c20-l2-k1")  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "no run is pre-started beside teams of 1 any more, redoing it" in r.stderr
    state = json.loads((out / "sweep.json").read_text())
    assert state["backoffs"][0] == {"run": "n01-c20-l2-k1", "deadline_miss_fraction": 0.05,
                                    "robots": 1, "prestart": False}  # fmt: skip
    spans = prestart_spans(times)
    assert len(spans) == 7  # the late run twice
    lone = sorted(float(p.read_text().split()[0]) for p in times.iterdir()
                  if p.read_text().split()[2] == "1")  # fmt: skip
    redo = next(s for s in spans if s[1] == lone[-1])
    after = [s for s in spans if s[1] > redo[1]]
    assert after and after[0][0] >= redo[2]  # not pre-started beside the redo
    assert any(nxt[0] < prev[2] for prev, nxt in zip(after, after[1:], strict=False))


def test_a_prestarted_run_whose_gate_stayed_shut_is_redone(env):
    """A pre-started run that reports its gate stayed shut (status gate_timeout) is redone,
    not counted as an attempt, and the sweep ends with every run done."""
    out = env["tmp"] / "out"
    r = run_sweep(env, out, "--jobs", "1", STANDIN_SLEEP="0.2",
                  STANDIN_GATE_SHUT_IDS="n02-c5-l2-k1")  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "n02-c5-l2-k1: its start gate stayed shut (the start gate" in r.stderr
    assert "redoing it" in r.stderr
    assert len(results(out)) == 6
    assert results(out)["n02-c5-l2-k1"]["status"] == "complete"
    state = json.loads((out / "sweep.json").read_text())
    assert {e["id"]: e["attempts"] for e in state["runs"]}["n02-c5-l2-k1"] == 1


def test_a_prestarted_run_whose_time_scale_changed_at_its_gate_starts_again(env):
    """Lone robots, the first run 2% late twice: pre-start beside them goes off (rule 3a),
    then their time scale down (rule 6); after three clean runs pre-start is back (rule 9a),
    and the third clean run at 85% takes the scale back up (rule 8) while the last run waits
    at its gate at 85%: that one is stopped and started again at the file's scale, not
    counted as an attempt."""
    sweep_file = env["tmp"] / "ones.toml"
    sweep_file.write_text(SWEEP.replace("robots = [1, 2, 3]", "robots = [1]").replace(
        "comm_range = [5, 20]", "comm_range = [5, 10, 15, 20, 25, 30]"))  # fmt: skip
    out = env["tmp"] / "out"
    r = run_sweep(dict(env, file=sweep_file), out, "--jobs", "1", STANDIN_SLEEP="0.3",
                  STANDIN_MISS="0.02", STANDIN_MISS_IDS="n01-c5-l2-k1")  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "no run is pre-started beside teams of 1 any more, redoing it" in r.stderr
    assert "time scales of teams of 1 up to 100%" in r.stderr
    assert "n01-c30-l2-k1: pre-started at a time scale changed since, starting it again" in (
        r.stderr
    )
    scales = {rid: res["config"]["time_scale"] for rid, res in results(out).items()}
    assert scales["n01-c25-l2-k1"] == 4.25 and scales["n01-c30-l2-k1"] == 5
    state = json.loads((out / "sweep.json").read_text())
    assert {e["id"]: e["attempts"] for e in state["runs"]}["n01-c30-l2-k1"] == 1
