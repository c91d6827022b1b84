"""One run: `testbed run --robots N --comm-range R --laser-range L --seed S --out DIR ...`.

Theory of operation. The run builds the world (ground truth, seeded start positions near one
corner, lasers) and a testbed network with one namespace per robot plus one for the display
(robot N+1, which does not explore). It starts `python -m node` in every namespace; each
connects to the world's body link (a Unix socket, off the emulated network). Then the step
clock runs: every step (100 ms of emulated time, `time_scale` times faster in wall time) the
world moves each robot toward the target its process last commanded, casts the lasers, feeds
all positions to the topology controller (links follow before the step goes on), and sends
each robot its frame (step, pose, scan) and the display its clock. Between frames it collects
the robots' commands until the step's deadline.

Processes: the robots and the display fork from one fork server (topology.forkserver) that
imported the node package and built the laser's tables once, so a dozen processes are ready
in a fraction of a second instead of each paying for numpy. The step loop runs at real-time
priority (SCHED_RR 2): it is the clock, and a robot woken by its frame must not preempt the
world before the other robots' frames are out.

Deadlines: a step's deadline is t0 + (step + 1) * period. The world misses it when its own
work overruns (the schedule then shifts by the overrun, so one hiccup counts once and the
achieved time scale shows the slip); a robot misses it when it has not answered the step's
frame by then. Both are counted; `deadline_miss_fraction` is misses over steps x (robots + 1).

The run ends when every robot that is still alive has finished (no reachable frontier on its
own map), or at the step cap. A robot process that dies before the end is recorded with its
exit status and step; the others carry on. Results follow docs/run-results.md:
config.json first, result.json last (atomically).
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import json
import logging
import math
import os
import re
import secrets
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import asdict, dataclass, field

import cv2
import numpy as np

from node.flood import MODES as FLOOD_MODES
from node.sched import deadline_priority
from testbed.errors import TestbedError, UsageError
from testbed.stalls import StallTracker
from testbed.world import body, render
from testbed.world.bodylink import BodyServer
from testbed.world.rays import Laser
from testbed.world.world import World
from testbed.world.worldmap import empty_terrain, free_space, load_png, start_positions
from topology.forkserver import ForkServer, ForkServerError, python_env

log = logging.getLogger(__name__)

STEP_S = 0.1  # emulated seconds per step
WORLD_RT_PRIORITY = 2  # the step loop's SCHED_RR priority (robots' motion control: 1)
WORLD_NICE = -10  # its nice value where real-time priority is refused
DEFAULT_SNAPSHOTS = (100, 250, 500, 1000, 2000)  # display PNGs (plus one at the end)
ROUTINGS = ("babel", "aodv", "none")
PROJECT_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# What the fork server imports once for every robot and the display (topology.forkserver).
NODE_PRELOAD = ["node.__main__", "node.robot", "node.goalnet", "node.display", "topology.names"]


@dataclass(frozen=True)
class RunConfig:
    robots: int
    comm_range: float
    laser_range: float = 2.0
    seed: int = 1
    time_scale: float = 1.0
    routing: str = "babel"
    map: str | None = None
    loss_pct: float = 0.0
    delay_ms: float = 0.0
    capture: bool = False
    max_steps: int = 3000
    # Beyond the contract's config keys (recorded too, so a run is reproducible):
    map_cell: float = 0.05
    laser_rays: int = 360
    speed: float = 0.1  # m per step (1 m/s)
    radius: float = 0.15
    plan_period: int = 20
    map_period: int = 10
    flood: str = "pruned"  # node.flood: "pruned" (self-pruning) or "blind"
    display_pos: tuple[float, float] | None = None  # default: the map's centre
    snapshots: tuple[int, ...] = ()
    kill: tuple[tuple[int, int], ...] = ()  # (robot, step): fault injection, SIGKILL

    def to_dict(self) -> dict:
        d = asdict(self)
        d["display_pos"] = list(self.display_pos) if self.display_pos else None
        d["snapshots"] = list(self.snapshots)
        d["kill"] = [f"{k}:{s}" for k, s in self.kill]
        return d


# -- command line ---------------------------------------------------------------------------


def _number(kind, lo=None, lo_open=False, name="value"):
    def conv(text: str):
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} {text!r} is not a number") from None
        if isinstance(v, float) and not math.isfinite(v):
            raise argparse.ArgumentTypeError(f"{name} {text!r} must be finite")
        if lo is not None and (v <= lo if lo_open else v < lo):
            rel = ">" if lo_open else ">="
            raise argparse.ArgumentTypeError(f"{name} {text!r} must be {rel} {lo}")
        return v

    return conv


def _kill(text: str) -> tuple[int, int]:
    m = re.fullmatch(r"r?(\d+):(\d+)", text)
    if not m:
        raise argparse.ArgumentTypeError(f"--kill {text!r} is not ROBOT:STEP (e.g. r2:150)")
    return int(m[1]), int(m[2])


def _point(text: str) -> tuple[float, float]:
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not X,Y in metres") from None
    return x, y


def _steps(text: str) -> tuple[int, ...]:
    try:
        return tuple(sorted({int(s) for s in text.split(",") if s.strip()}))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a list of steps") from None


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The `testbed run` options."""
    a = parser.add_argument
    a("--robots", type=_number(int, 1, name="robots"), required=True, help="team size")
    a("--comm-range", type=_number(float, 0, True, "comm range"), required=True, help="metres")
    a("--laser-range", type=_number(float, 0, True, "laser range"), default=2.0, help="metres")
    a("--seed", type=_number(int, 0, name="seed"), default=1)
    a("--out", required=True, help="run directory to write")
    a("--time-scale", type=_number(float, 0, True, "time scale"), default=1.0)
    a("--routing", choices=ROUTINGS, default="babel")
    a("--map", help="PNG map (dark pixels are obstacles); default: empty 20 x 20 m")
    a("--map-cell", type=_number(float, 0, True, "map cell"), default=0.05, help="m per pixel")
    a("--loss", type=_number(float, 0, name="loss"), default=0.0, help="percent, every link")
    a("--delay", type=_number(float, 0, name="delay"), default=0.0, help="ms, every link")
    a("--capture", action="store_true", help="write pcaps/rK.pcap")
    a("--max-steps", type=_number(int, 1, name="max steps"), default=3000)
    a("--laser-rays", type=_number(int, 4, name="laser rays"), default=360)
    a("--speed", type=_number(float, 0, True, "speed"), default=1.0, help="m/s")
    a("--map-period", type=_number(int, 1, name="map period"), default=10,
      help="steps between a robot's map floods (default 10)")  # fmt: skip
    a(
        "--flood",
        choices=FLOOD_MODES,
        default="pruned",
        help="map flooding: self-pruning (default) or blind (every robot relays every flood)",
    )
    a("--display-pos", type=_point, help="X,Y of the display (default: map centre)")
    a("--snapshots", type=_steps, default=(),
      help="display snapshot steps, e.g. 200,600 (default 100,250,500,1000,2000; always one "
           "at the end)")  # fmt: skip
    a("--kill", type=_kill, action="append", default=[], help="ROBOT:STEP, SIGKILL (testing)")
    a("--name", help="testbed name (default: random 'run' + 4 hex digits)")
    a("--quiet", action="store_true", help="no progress line")


def config_from_args(args: argparse.Namespace) -> RunConfig:
    if args.loss > 100:
        raise UsageError(f"loss {args.loss}% is more than 100%")
    if args.robots > 50:
        raise UsageError(f"at most 50 robots ({args.robots} asked)")
    for k, _ in args.kill:
        if not 1 <= k <= args.robots:
            raise UsageError(f"--kill names robot {k}, but the team is r1..r{args.robots}")
    return RunConfig(
        robots=args.robots, comm_range=args.comm_range, laser_range=args.laser_range,
        seed=args.seed, time_scale=args.time_scale, routing=args.routing, map=args.map,
        loss_pct=args.loss, delay_ms=args.delay, capture=args.capture,
        max_steps=args.max_steps, map_cell=args.map_cell, laser_rays=args.laser_rays,
        speed=args.speed * STEP_S, display_pos=args.display_pos, snapshots=args.snapshots,
        map_period=args.map_period, flood=args.flood,
        kill=tuple(args.kill),
    )  # fmt: skip


def main(args: argparse.Namespace) -> int:
    """`testbed run`: 0 when the run completed, 1 when it ended badly (see result.json)."""
    cfg = config_from_args(args)
    name = args.name or "run" + secrets.token_hex(2)
    result = run(cfg, args.out, name, progress=not args.quiet)
    if result["status"] != "complete":
        sys.stderr.write(f"testbed run: {result['status']}: {result['status_detail']}\n")
        return 1
    return 0


# -- the run --------------------------------------------------------------------------------


@dataclass
class RobotRecord:
    k: int
    proc: subprocess.Popen | None = None
    last_cmd: int = -1
    finish_step: int | None = None
    crashed: bool = False
    crash_step: int | None = None
    exit_status: int | None = None
    missed: int = 0
    missed_steps: list = field(default_factory=list)
    killed_at: int | None = None
    extra: dict = field(default_factory=dict)


def _write_json(path: str, obj) -> None:
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        json.dump(obj, f, indent=1)
        f.write("\n")
    os.replace(tmp, path)


def run(cfg: RunConfig, out: str, name: str, progress: bool = True) -> dict:
    """Do one run into directory `out`; returns the result dict (also in out/result.json)."""
    from topology.network import Network, preflight
    from topology.spec import Impairment, NetworkSpec

    try:
        truth = load_png(cfg.map, cfg.map_cell) if cfg.map else empty_terrain()
    except UsageError:
        raise
    rng = np.random.default_rng(cfg.seed)
    starts = start_positions(truth, cfg.robots, rng, cfg.radius)
    # Each robot's timer starts at its own phase (seeded), as robots booted one by one would.
    phases = [int(v) for v in rng.integers(0, cfg.plan_period, size=cfg.robots)]
    space = free_space(truth, starts)
    laser = Laser(cfg.laser_range, cfg.laser_rays, truth.cell)
    world = World(truth, starts, laser, space, cfg.speed, cfg.radius)
    w_m, h_m = truth.size_m
    display_pos = cfg.display_pos or (w_m / 2, h_m / 2)
    n = cfg.robots
    display_k = n + 1
    try:
        spec = NetworkSpec(
            name=name,
            positions=tuple(starts) + (tuple(display_pos),),
            comm_range=cfg.comm_range,
            routing=cfg.routing,
            impairment=Impairment(loss_pct=cfg.loss_pct, delay_ms=cfg.delay_ms),
            capture_dir=os.path.join(os.path.abspath(out), "pcaps") if cfg.capture else None,
            time_scale=cfg.time_scale,
        )
    except ValueError as e:
        raise UsageError(str(e)) from None
    preflight(spec)

    os.makedirs(out, exist_ok=True)
    for sub in ("robots", "display") + (("pcaps",) if cfg.capture else ()):
        os.makedirs(os.path.join(out, sub), exist_ok=True)
    with contextlib.suppress(FileNotFoundError):
        os.unlink(os.path.join(out, "result.json"))
    for f in os.listdir(os.path.join(out, "robots")):
        if f.endswith(".events.jsonl"):
            os.unlink(os.path.join(out, "robots", f))
    config = cfg.to_dict()
    config.update(map_size=list(truth.shape), starts=[list(p) for p in starts], timer_phases=phases,
                  display=display_k, display_pos=list(display_pos), name=name)  # fmt: skip
    _write_json(os.path.join(out, "config.json"), config)

    robots = {k: RobotRecord(k) for k in range(1, n + 1)}
    timing: dict[str, float] = {}
    status, detail = "error", "the run did not start"
    steps_done = 0
    missed_world = 0
    wall = 0.0
    t_start = time.monotonic()
    links_f = open(os.path.join(out, "links.csv"), "w", newline="")  # noqa: SIM115
    cov_f = open(os.path.join(out, "coverage.csv"), "w", newline="")  # noqa: SIM115
    links_w, cov_w = csv.writer(links_f), csv.writer(cov_f)
    links_w.writerow(["step", "event", "i", "j"])
    cov_w.writerow(["step", "coverage"])
    display_proc = None
    server = None
    parts: dict[str, float] = {}  # wall seconds of each part of the run
    timing["parts"] = parts
    mark = [time.monotonic()]

    def phase(name: str) -> None:
        now = time.monotonic()
        parts[name] = round(now - mark[0], 3)
        mark[0] = now

    env = python_env()
    env["OPENBLAS_NUM_THREADS"] = "1"  # a robot's numpy needs no thread pool of its own
    forks = None
    try:
        # Started first, so that its imports overlap the network's bring-up.
        forks = ForkServer(
            NODE_PRELOAD, env=env,
            warm=[["testbed.world.rays", "warm", [cfg.laser_range, cfg.laser_rays, truth.cell]]],
            label=os.path.abspath(out),
        )  # fmt: skip
        with Network(spec) as net:
            phase("network_up")
            server = BodyServer(os.path.join(net.state_dir, "body.sock"))
            for i, j in sorted(net.links()):
                links_w.writerow([0, "add", i, j])
            common = [
                "--robots", str(n), "--body", server.path,
                "--map-size", f"{truth.shape[0]}x{truth.shape[1]}", "--cell", str(truth.cell),
                "--laser-range", str(cfg.laser_range), "--laser-rays", str(cfg.laser_rays),
                "--speed", str(cfg.speed), "--radius", str(cfg.radius),
                "--plan-period", str(cfg.plan_period), "--map-period", str(cfg.map_period),
                "--time-scale", str(cfg.time_scale), "--flood", cfg.flood,
            ]  # fmt: skip
            outa = os.path.abspath(out)
            for k in range(1, n + 1):
                argv = common + [
                    "--robot", f"r{k}", "--timer-phase", str(phases[k - 1]),
                    "--events", os.path.join(outa, "robots", f"r{k}.events.jsonl"),
                ]  # fmt: skip
                robots[k].proc = _start_node(
                    net, forks, k, argv, os.path.join(outa, "robots", f"r{k}.log"), "robot"
                )
            snaps = ",".join(str(s) for s in cfg.snapshots or DEFAULT_SNAPSHOTS)
            argv = common + [
                "--robot", f"r{display_k}", "--role", "display",
                "--out-dir", os.path.join(outa, "display"),
                "--events", os.path.join(outa, "display", "events.jsonl"),
                "--snapshots", snaps,
            ]  # fmt: skip
            display_proc = _start_node(
                net, forks, display_k, argv, os.path.join(outa, "display", "display.log"),
                "display",
            )  # fmt: skip
            _wait_connected(server, robots, display_k, display_proc, 60.0 + 3.0 * n)
            phase("processes_ready")
            missing = sorted(set(robots) - set(server.robots))
            if missing or display_k not in server.displays:
                dead = [k for k in robots if robots[k].proc.poll() is not None]
                raise TestbedError(
                    f"robot processes did not connect to the world: {missing or 'display'}"
                    + (
                        f" (r{dead[0]} exited with {robots[dead[0]].proc.returncode})"
                        if dead
                        else ""
                    )
                )
            with _clock_priority() as timing["priority"]:
                status, detail, steps_done, missed_world, wall = _step_loop(
                    cfg, world, net, server, robots, display_k, display_pos, links_w, cov_w,
                    progress, timing,
                )  # fmt: skip
            phase("steps")
            _end(server, robots, display_k, display_proc, steps_done)
            phase("processes_ended")
            _collect_routing(net, cfg, out)
            phase("routing_stopped")
        phase("network_down")
    except (TestbedError, ForkServerError) as e:
        status, detail = "error", str(e).splitlines()[0] if str(e) else type(e).__name__
        log.error("run failed: %s", detail)
    except KeyboardInterrupt:
        status, detail = "interrupted", "interrupted (SIGINT or SIGTERM) before the end"
    finally:
        links_f.close()
        cov_f.close()
        _write_clock(os.path.join(out, "clock.csv"), timing.get("clock", []))
        if server is not None:
            server.close()
        if forks is not None:
            forks.close()
    result = _results(cfg, config, out, world, robots, status, detail, steps_done,
                      missed_world, wall, time.monotonic() - t_start, timing)  # fmt: skip
    return result


def _clock_priority():
    """Schedule the step loop ahead of the robots it simulates: it keeps the clock that every
    robot is measured against. Round-robin real-time priority 2, above the robots' motion
    control (node.robot) and everything else (a robot woken by its frame
    then cannot preempt the world before the other frames are out; the loop sleeps between
    steps, and the kernel's RT throttling bounds it anyway), else nice -10, else nothing.
    This thread only and for the step loop only; needs root, as runs do. A context manager
    that yields what it got."""
    return deadline_priority(WORLD_RT_PRIORITY, WORLD_NICE)


def _step_loop(cfg, world, net, server, robots, display_k, display_pos, links_w, cov_w,
               progress, timing):  # fmt: skip
    n = cfg.robots
    period = STEP_S / cfg.time_scale
    kills = dict()
    for k, s in cfg.kill:
        kills.setdefault(s, []).append(k)
    missed_world = 0
    timing.update(net_s=0.0, net_max_s=0.0, world_s=0.0, scan_s=0.0, send_s=0.0)
    clock = timing.setdefault("clock", [])  # CLOCK_MONOTONIC when each step's frames went out
    tty = progress and sys.stderr.isatty()
    last_print = 0.0
    step = 0
    scans = [world.scan(i) for i in range(n)]
    cov_w.writerow([0, f"{world.coverage():.5f}"])
    stalls = StallTracker(period)
    timing["stalls"] = stalls
    t0 = time.monotonic()
    anchor = t0  # step k's deadline is anchor + (k + 1) * period
    cpu0 = time.process_time()

    def send_frames(step: int) -> None:
        now = time.monotonic()
        clock.append(round(now, 4))
        for k in range(1, n + 1):
            r = robots[k]
            if r.crashed:
                continue
            b = world.bodies[k - 1]
            server.send(k, body.frame(step, b.x, b.y, b.theta, scans[k - 1], now))
        server.send(display_k, body.frame(step, display_pos[0], display_pos[1], 0.0, None), True)

    send_frames(0)
    status, detail = "step_cap", f"the step cap ({cfg.max_steps}) was reached"
    while True:
        deadline = anchor + (step + 1) * period
        while True:
            left = deadline - time.monotonic()
            for k, msg in server.poll(max(0.0, left)):
                if not 1 <= k <= n:
                    continue
                r = robots[k]
                if msg[0] == "cmd":
                    r.last_cmd = max(r.last_cmd, msg[1])
                    world.command(k - 1, msg[2])
                elif msg[0] == "done" and r.finish_step is None:
                    r.finish_step = step
            if left <= 0:
                break
        stalls.late(step, time.monotonic() - deadline)
        # The step is over: who answered its frame in time?
        for r in robots.values():
            if not r.crashed and r.last_cmd < step:
                r.missed += 1
                stalls.count(step, 1)
                if len(r.missed_steps) < 1000:
                    r.missed_steps.append(step)
        step += 1
        tw = time.monotonic()
        world.move()
        tn = time.monotonic()
        added, removed = net.set_positions(world.positions() + [display_pos])
        timing["net_s"] += time.monotonic() - tn
        timing["net_max_s"] = max(timing["net_max_s"], time.monotonic() - tn)
        for i, j in sorted(removed):
            links_w.writerow([step, "remove", i, j])
        for i, j in sorted(added):
            links_w.writerow([step, "add", i, j])
        for k in kills.get(step, []):
            r = robots[k]
            with contextlib.suppress(ProcessLookupError):
                os.kill(r.proc.pid, signal.SIGKILL)
            r.killed_at = step
        for k, r in robots.items():
            if not r.crashed and r.proc.poll() is not None:
                r.crashed, r.crash_step, r.exit_status = True, step, r.proc.returncode
                world.bodies[k - 1].alive = False
                log.warning("r%d exited with status %s at step %d", k, r.exit_status, step)
        ts = time.monotonic()
        scans = [world.scan(i) if not robots[i + 1].crashed else None for i in range(n)]
        cov = world.coverage()
        cov_w.writerow([step, f"{cov:.5f}"])
        tf = time.monotonic()
        timing["scan_s"] += tf - ts
        send_frames(step)
        timing["send_s"] += time.monotonic() - tf
        timing["world_s"] += time.monotonic() - tw
        late = time.monotonic() - (anchor + (step + 1) * period)
        if late > 0:
            # The world's own work ran past this step's deadline: count it once and move the
            # schedule (catching up by running steps back to back would squeeze the robots).
            missed_world += 1
            stalls.late(step, late)
            stalls.count(step, 1)
            anchor += late
            if len(timing.setdefault("missed_steps", [])) < 1000:
                timing["missed_steps"].append([step, round(late * 1000, 1)])
        live = [r for r in robots.values() if not r.crashed]
        now = time.monotonic()
        if progress and (now - last_print > (0.5 if tty else 10.0)):
            last_print = now
            done = sum(1 for r in live if r.finish_step is not None)
            scale = step * STEP_S / max(1e-9, now - t0)
            line = (
                f"step {step}/{cfg.max_steps}  coverage {100 * cov:5.1f}%  "
                f"finished {done}/{n}  crashed {n - len(live)}  scale {scale:.1f}x  "
                f"missed {missed_world + sum(r.missed for r in robots.values())}"
            )
            sys.stderr.write(("\r" + line + "  ") if tty else (line + "\n"))
            sys.stderr.flush()
        if live and all(r.finish_step is not None for r in live):
            status, detail = "complete", f"all robots finished by step {step}"
            break
        if not live:
            status, detail = "robot_crashed", "every robot process died"
            break
        if step >= cfg.max_steps:
            break
    wall = time.monotonic() - t0
    timing["world_cpu_s"] = time.process_time() - cpu0
    if tty:
        sys.stderr.write("\n")
    crashed = [r for r in robots.values() if r.crashed]
    if crashed and status != "robot_crashed":
        r = crashed[0]
        status = "robot_crashed"
        detail = f"r{r.k} exited with status {r.exit_status} at step {r.crash_step}" + (
            f"; {len(crashed) - 1} more" if len(crashed) > 1 else ""
        )
    elif crashed:
        r = crashed[0]
        detail = f"r{r.k} exited with status {r.exit_status} at step {r.crash_step}; all died"
    return status, detail, step, missed_world, wall


def _write_clock(path: str, clock: list[float]) -> None:
    """clock.csv: when (CLOCK_MONOTONIC, the clock robots log receipts with) each step began;
    what lets testbed.analysis.runcheck place a receipt at the world's step, not the robot's."""
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["step", "t"])
        w.writerows(enumerate(clock))


def _start_node(net, forks, k: int, argv: list[str], log_path: str, role: str):
    """`python -m node ARGV` in robot k's namespace, forked from the fork server (the imports
    are already done there), recorded with the testbed so that teardown stops it."""
    with open(log_path, "w"):
        pass  # the child appends: the log starts empty
    proc = forks.spawn(net.robot_ns(k), "node.__main__", argv, log_path, title=f"r{k} {role}")
    net.adopt(k, proc, role)
    return proc


def _wait_connected(server, robots, display_k, display_proc, timeout: float) -> None:
    """Wait until every robot and the display said hello, or one of them died, or timeout."""
    deadline = time.monotonic() + timeout
    procs = [r.proc for r in robots.values()] + [display_proc]
    while time.monotonic() < deadline:
        server.wait_for(set(robots), {display_k}, timeout=0.2)
        if set(robots) <= set(server.robots) and display_k in server.displays:
            return
        if any(p.poll() is not None for p in procs):
            return


def _end(server, robots, display_k, display_proc, step) -> None:
    """Tell everyone the run is over and give them a moment to write their logs."""
    for k, r in robots.items():
        if not r.crashed:
            server.send(k, body.END)
    server.send(display_k, body.END, True)
    deadline = time.monotonic() + 15.0
    procs = [r.proc for r in robots.values() if not r.crashed] + [display_proc]
    for p in procs:
        with contextlib.suppress(subprocess.TimeoutExpired):
            p.wait(timeout=max(0.1, deadline - time.monotonic()))
    for r in robots.values():
        if not r.crashed:
            r.exit_status = r.proc.poll()


def _collect_routing(net, cfg, out) -> None:
    """Copy the routing daemons' logs (and AODV statistics) before the testbed goes away."""
    if cfg.routing == "none":
        return
    # Stop the daemons first so that they write their final statistics and logs.
    net.stop(cfg.routing)
    if cfg.routing == "aodv":
        os.makedirs(os.path.join(out, "aodv"), exist_ok=True)
    os.makedirs(os.path.join(out, "routing"), exist_ok=True)
    for k in range(1, cfg.robots + 2):
        src = os.path.join(net.state_dir, f"r{k}.{cfg.routing}.log")
        if os.path.exists(src):
            shutil.copy(src, os.path.join(out, "routing", f"r{k}.{cfg.routing}.log"))
        stats = os.path.join(net.state_dir, f"r{k}.aodv.json")
        if cfg.routing == "aodv" and os.path.exists(stats):
            shutil.copy(stats, os.path.join(out, "aodv", f"r{k}.json"))


# -- results --------------------------------------------------------------------------------


def read_events(path: str) -> list[dict]:
    out = []
    try:
        with open(path) as f:
            for line in f:
                with contextlib.suppress(json.JSONDecodeError):
                    out.append(json.loads(line))
    except FileNotFoundError:
        pass
    return out


def _results(cfg, config, out, world, robots, status, detail, steps, missed_world, wall,
             total_wall, timing) -> dict:  # fmt: skip
    t_results = time.monotonic()
    n = cfg.robots
    robot_out = {}
    for k, r in robots.items():
        ev = read_events(os.path.join(out, "robots", f"r{k}.events.jsonl"))
        plans = [{"step": e["step"], "cause": e["cause"]} for e in ev if e["e"] == "plan"]
        sent: dict[str, int] = {}
        received: dict[str, int] = {}
        for e in ev:
            if e["e"] == "send":
                sent[e["kind"]] = sent.get(e["kind"], 0) + 1
            elif e["e"] == "recv":
                received[e["kind"]] = received.get(e["kind"], 0) + 1
        summary = next((e for e in reversed(ev) if e["e"] == "summary"), {})
        b = world.bodies[k - 1]
        rec = {
            "finish_step": r.finish_step,
            "crashed": r.crashed,
            "exit_status": r.exit_status,
            "plans": plans,
            "messages": {"sent": sent, "received": received},
            "path_length_m": round(b.path_length, 3),
        }
        robot_out[f"r{k}"] = rec
        detail_rec = dict(rec)
        detail_rec.update(
            crash_step=r.crash_step, killed_at=r.killed_at, deadlines_missed=r.missed,
            deadlines_missed_steps=r.missed_steps,
            collisions=b.collisions, final_pose=[round(b.x, 3), round(b.y, 3)],
            plan_details=[
                {k2: e.get(k2) for k2 in ("step", "cause", "status", "goal", "cost", "ms")}
                for e in ev if e["e"] == "plan"
            ],
            send_failed=summary.get("send_failed"), flood=summary.get("flood"),
            frames_skipped=summary.get("frames_skipped"),
            plan_ms_median=summary.get("plan_ms_median"),
            cpu_s=summary.get("cpu_s"), max_rss_mb=summary.get("max_rss_mb"),
            busy_s=summary.get("busy_s"), frames=summary.get("frames"),
            latency_ms=summary.get("latency_ms"), thread_cpu_s=summary.get("thread_cpu_s"),
        )  # fmt: skip
        _write_json(os.path.join(out, "robots", f"r{k}.json"), detail_rec)
    missed = missed_world + sum(r.missed for r in robots.values())
    checks = max(1, steps * (n + 1))
    stalls = timing.get("stalls")
    stall_summary = (
        stalls.summary() if stalls else {"events": 0, "stalled_s": 0.0, "deadlines_missed": 0}
    )
    achieved = steps * STEP_S / wall if wall > 0 else 0.0
    try:
        _paths_png(world, os.path.join(out, "paths.png"))
    except Exception as e:  # a picture must not lose the results
        log.warning("paths.png: %s", e)
    disp = _display_coverage(out, world)
    result = {
        "format": 1,
        "config": {k: config[k] for k in (
            "robots", "comm_range", "laser_range", "seed", "time_scale", "routing", "map",
            "loss_pct", "delay_ms", "capture", "max_steps")},
        "status": status,
        "status_detail": detail,
        "steps": steps,
        "coverage_final": round(world.coverage(), 5),
        "time_scale_requested": cfg.time_scale,
        "time_scale_achieved": round(achieved, 3),
        "deadlines_missed": missed,
        "deadline_miss_fraction": round(missed / checks, 5) if steps else 0.0,
        "deadlines_missed_world": missed_world,
        # Misses while the host stalled the whole machine (testbed.stalls), and the fraction
        # without them: what a lower time scale could have avoided.
        "host_stalls": stall_summary,
        "deadline_miss_fraction_outside_stalls": (
            round((missed - stall_summary["deadlines_missed"]) / checks, 5) if steps else 0.0
        ),
        "wall_time_s": round(total_wall, 2),
        "step_loop_wall_s": round(wall, 2),
        "wall_parts_s": dict(timing.get("parts", {})),
        "world_priority": timing.get("priority"),
        "display": {"robot": n + 1, "coverage_final": disp},
        "world_timing_s": {
            k: round(v, 3) for k, v in timing.items() if isinstance(v, float)
        },
        "world_missed_steps_ms_late": timing.get("missed_steps", []),
        "robots": robot_out,
    }  # fmt: skip
    result["config"]["extra"] = {k: v for k, v in config.items() if k not in result["config"]}
    result["wall_parts_s"]["results"] = round(time.monotonic() - t_results, 3)
    _write_json(os.path.join(out, "result.json"), result)
    return result


def _display_coverage(out: str, world: World) -> float | None:
    try:
        t = np.load(os.path.join(out, "display", "map.npy"))
    except (OSError, ValueError):
        return None
    if t.shape != world.free_space.shape:
        return None
    known = (t == 1) & world.free_space
    return round(float(known.sum()) / world.free_total, 5)


def _paths_png(world: World, path: str, scale: int = 2) -> None:
    t = np.zeros(world.truth.shape, dtype=np.uint8)  # unknown where nobody looked
    t[world.seen & ~world.truth.occupied] = 1
    t[world.truth.occupied] = 2
    img = render.map_image(t, scale)
    paths = {k + 1: p[:: max(1, len(p) // 2000)] + p[-1:] for k, p in enumerate(world.paths)}
    render.draw_paths(img, paths, world.truth.cell, scale, thickness=2)
    cv2.imwrite(path, img)


if __name__ == "__main__":  # `python -m testbed.run` is `testbed run`
    from testbed.cli import main as cli_main

    sys.exit(cli_main(["run", *sys.argv[1:]]))
