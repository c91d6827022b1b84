"""One run: `testbed run --robots N --comm-range R --laser-range L --seed S --out DIR ...`.

Theory of operation. A `Run` goes through four stages, each a method, its state on itself:

- `prepare()` builds the world (ground truth, seeded start positions near one corner, lasers)
  and the description of the testbed network (one namespace per robot plus one for the
  display, robot N+1, which does not explore), checks that this machine can build it, and
  writes config.json.
- `start()` brings the network up, starts `python -m node` in every namespace (forked from a
  fork server that imported the node package and built the laser's tables once, so a dozen
  processes are ready in a fraction of a second instead of each paying for numpy), and waits
  until each has connected to the world's body link (a Unix socket, off the emulated network).
- `step()` is one tick of the clock (100 ms of emulated time, `time_scale` times faster in
  wall time): it collects the robots' commands until the step's deadline, moves each robot
  toward the target its process last commanded, feeds all positions to the topology
  controller (links follow before the step goes on), casts the lasers and sends each robot
  its frame (step, pose, scan) and the display its clock. It says whether the run goes on.
  The loop of steps runs at real-time priority (SCHED_RR 2): it is the clock, and a robot
  woken by its frame must not preempt the world before the other robots' frames are out.
- `finish()` tells the processes the run is over, keeps the routing daemons' logs, takes the
  network down and writes the results.

`execute()` runs the four in order and turns a failure into a recorded status: whatever
happens, result.json is written (docs/run-results.md: config.json first, result.json last,
atomically), and the network is torn down.

Deadlines: a step's deadline is t0 + (step + 1) * period. The world misses it when its own
work overruns (the schedule then shifts by the overrun, so one hiccup counts once and the
achieved time scale shows the slip); a robot misses it when it has not answered the step's
frame by then. Both are counted; `deadline_miss_fraction` is misses over steps x (robots + 1).

The run ends when every robot that is still alive has finished (no reachable frontier on its
own map), or at the step cap. A robot process that dies before the end is recorded with its
exit status and step; the others carry on. See docs/architecture.md for the process tree.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import logging
import os
import secrets
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from node import body
from node.launch import NodeArgs
from node.rays import Laser
from node.sched import deadline_priority
from testbed.errors import TestbedError, UsageError
from testbed.runconfig import STEP_S, RunConfig, add_arguments, config_from_args
from testbed.stalls import StallTracker
from testbed.world.bodylink import BodyServer
from testbed.world.world import World
from testbed.world.worldmap import empty_terrain, free_space, load_png, start_positions
from topology.forkserver import ForkServer, ForkServerError, python_env
from topology.jsonfile import write_json_atomic

log = logging.getLogger(__name__)

WORLD_RT_PRIORITY = 2  # the step loop's SCHED_RR priority (robots' motion control: 1)
WORLD_NICE = -10  # its nice value where real-time priority is refused
DEFAULT_SNAPSHOTS = (100, 250, 500, 1000, 2000)  # display PNGs (plus one at the end)
PROJECT_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# What the fork server imports once for every robot and the display (topology.forkserver).
NODE_PRELOAD = ["node.__main__", "node.robot", "node.goalnet", "node.display", "topology.names"]
CONNECT_TIMEOUT_S = 60.0  # plus 3 s per robot: every process must have said hello by then
END_GRACE_S = 15.0  # for the processes to write their logs after END
MAX_MISSED_STEPS_KEPT = 1000  # per robot, and for the world: which steps were missed
__all__ = ["PROJECT_ROOT", "Run", "RunConfig", "add_arguments", "main", "run"]


def main(args: argparse.Namespace) -> int:
    """`testbed run`: 0 when the run completed, 1 when it ended badly (see result.json)."""
    cfg = config_from_args(args)
    name = args.name or "run" + secrets.token_hex(2)
    result = run(cfg, args.out, name, progress=not args.quiet)
    if result["status"] != "complete":
        sys.stderr.write(f"testbed run: {result['status']}: {result['status_detail']}\n")
        return 1
    return 0


def run(cfg: RunConfig, out: str, name: str, progress: bool = True) -> dict:
    """Do one run into directory `out`; returns the result dict (also in out/result.json)."""
    return Run(cfg, out, name, progress).execute()


@dataclass
class RobotRecord:
    """What the world knows of one robot's process during the run."""

    k: int
    proc: subprocess.Popen | None = None
    last_cmd: int = -1  # the latest step whose frame it answered
    finish_step: int | None = None
    crashed: bool = False
    crash_step: int | None = None
    exit_status: int | None = None
    missed: int = 0
    missed_steps: list = field(default_factory=list)
    killed_at: int | None = None


@dataclass
class StepTiming:
    """Wall seconds the world spent on each part of its steps (result.json's
    world_timing_s), and when each step's frames went out (clock.csv)."""

    net_s: float = 0.0
    net_max_s: float = 0.0
    world_s: float = 0.0
    scan_s: float = 0.0
    send_s: float = 0.0
    world_cpu_s: float = 0.0
    clock: list[float] = field(default_factory=list)  # CLOCK_MONOTONIC of each step's frames
    missed_steps: list[list] = field(default_factory=list)  # [step, ms late] of the world's

    def seconds(self) -> dict[str, float]:
        return {
            k: round(getattr(self, k), 3)
            for k in ("net_s", "net_max_s", "world_s", "scan_s", "send_s", "world_cpu_s")
        }


class Run:
    """One run into directory `out` (see the module docstring for its stages)."""

    def __init__(self, cfg: RunConfig, out: str, name: str, progress: bool = True):
        self.cfg = cfg
        self.out = os.path.abspath(out)
        self.name = name
        self.progress = progress
        self.n = cfg.robots
        self.live = None  # --view: testbed.view.live.LiveServer
        self._positions: list = []
        self.display_k = cfg.robots + 1
        self.robots = {k: RobotRecord(k) for k in range(1, cfg.robots + 1)}
        self.status, self.detail = "error", "the run did not start"
        self.step_no = 0  # the last step done; its frames are out
        self.missed_world = 0
        self.loop_wall_s = 0.0
        self.parts: dict[str, float] = {}  # wall seconds of each stage of the run
        self.priority: str | None = None  # what the step loop's thread got
        self.timing: StepTiming | None = None  # set when the step loop starts
        self._t_start = time.monotonic()
        self._mark = self._t_start
        self._stack = contextlib.ExitStack()  # what start() opened, closed by finish()
        self.forks: ForkServer | None = None
        self.net = None
        self.server: BodyServer | None = None
        self.display_proc = None

    # -- the whole run ------------------------------------------------------------------------

    def execute(self) -> dict:
        """prepare, start, step until the end, finish; a failure after prepare() becomes the
        run's status, and result.json is written whatever happened."""
        self.prepare()
        try:
            try:
                self.start()
                with deadline_priority(WORLD_RT_PRIORITY, WORLD_NICE) as self.priority:
                    self._start_clock()
                    while self.step():
                        pass
                    self._stop_clock()
                self._phase("steps")
                self._end_processes()
            finally:
                self._stack.close()  # routing logs kept, network down, servers closed
            self._phase("network_down")
        except (TestbedError, ForkServerError) as e:
            self.status, self.detail = (
                "error",
                str(e).splitlines()[0] if str(e) else type(e).__name__,
            )
            log.error("run failed: %s", self.detail)
        except KeyboardInterrupt:
            self.status, self.detail = (
                "interrupted",
                "interrupted (SIGINT or SIGTERM) before the end",
            )
        return self.finish()

    def _phase(self, name: str) -> None:
        now = time.monotonic()
        self.parts[name] = round(now - self._mark, 3)
        self._mark = now

    # -- prepare ------------------------------------------------------------------------------

    def prepare(self) -> None:
        """The world, the network's description and config.json; raises UsageError for a
        run this machine cannot do (nothing is started yet)."""
        from topology.network import preflight
        from topology.spec import Impairment, NetworkSpec

        cfg = self.cfg
        truth = load_png(cfg.map, cfg.map_cell) if cfg.map else empty_terrain()
        rng = np.random.default_rng(cfg.seed)
        starts = start_positions(truth, cfg.robots, rng, cfg.radius, cfg.start)
        # Each robot's timer starts at its own phase (seeded), as robots booted one by one would.
        self.phases = [int(v) for v in rng.integers(0, cfg.plan_period, size=cfg.robots)]
        laser = Laser(cfg.laser_range, cfg.laser_rays, truth.cell)
        self.truth = truth
        self.world = World(truth, starts, laser, free_space(truth, starts), cfg.speed, cfg.radius)
        w_m, h_m = truth.size_m
        self.display_pos = cfg.display_pos or (w_m / 2, h_m / 2)
        try:
            self.spec = NetworkSpec(
                name=self.name,
                positions=tuple(starts) + (tuple(self.display_pos),),
                comm_range=cfg.comm_range,
                routing=cfg.routing,
                aodv_profile=cfg.aodv_profile,
                range_model=cfg.range_model,
                map_png=os.path.abspath(cfg.map) if cfg.map else None,
                map_cell=cfg.map_cell,
                wall_loss_pct=cfg.wall_loss_pct,
                impairment=Impairment(loss_pct=cfg.loss_pct, delay_ms=cfg.delay_ms),
                capture_dir=self._path("pcaps") if cfg.capture else None,
                time_scale=cfg.time_scale,
            )
        except ValueError as e:
            raise UsageError(str(e)) from None
        preflight(self.spec)
        self._clear_directory()
        self.config = cfg.to_dict()
        self.config.update(map_size=list(truth.shape), starts=[list(p) for p in starts],
                           timer_phases=self.phases, display=self.display_k,
                           display_pos=list(self.display_pos), name=self.name)  # fmt: skip
        write_json_atomic(self._path("config.json"), self.config)

    def _path(self, *parts: str) -> str:
        return os.path.join(self.out, *parts)

    def _clear_directory(self) -> None:
        """The run directory, without what an earlier attempt left that this run appends to
        or that would say it is finished."""
        for sub in ("robots", "display") + (("pcaps",) if self.cfg.capture else ()):
            os.makedirs(self._path(sub), exist_ok=True)
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self._path("result.json"))
        for f in os.listdir(self._path("robots")):
            if f.endswith(".events.jsonl"):
                os.unlink(self._path("robots", f))

    # -- start --------------------------------------------------------------------------------

    def start(self) -> None:
        """The network up and every robot process connected to its body, or TestbedError."""
        from topology.network import Network

        self.links_f = self._stack.enter_context(open(self._path("links.csv"), "w", newline=""))
        self.cov_f = self._stack.enter_context(open(self._path("coverage.csv"), "w", newline=""))
        self.pos_f = self._stack.enter_context(open(self._path("positions.csv"), "w", newline=""))
        self.links_w, self.cov_w = csv.writer(self.links_f), csv.writer(self.cov_f)
        self.pos_w = csv.writer(self.pos_f)
        self.pos_w.writerow(["step"] + [f"{a}{k}" for k in range(1, self.n + 1) for a in "xy"])
        self.links_w.writerow(["step", "event", "i", "j"])
        self.cov_w.writerow(["step", "coverage"])
        self._stack.callback(self._write_clock)
        env = python_env()
        env["OPENBLAS_NUM_THREADS"] = "1"  # a robot's numpy needs no thread pool of its own
        # Started first, so that its imports overlap the network's bring-up.
        laser = [self.cfg.laser_range, self.cfg.laser_rays, self.truth.cell]
        self.forks = ForkServer(NODE_PRELOAD, env=env, label=self.out,
                                warm=[["node.rays", "warm", laser]])  # fmt: skip
        self._stack.callback(self.forks.close)
        self.net = self._stack.enter_context(Network(self.spec))
        # Runs before the network goes down: the daemons' last words are kept.
        self._stack.callback(self._keep_routing_files)
        self._phase("network_up")
        self.server = BodyServer(os.path.join(self.net.state_dir, "body.sock"))
        self._stack.callback(self.server.close)
        for i, j in sorted(self.net.links()):
            self.links_w.writerow([0, "add", i, j])
        for k, r in self.robots.items():
            r.proc = self._start_node(
                k, "robot", self._node_argv(k), self._path("robots", f"r{k}.log")
            )
        self.display_proc = self._start_node(
            self.display_k, "display", self._display_argv(), self._path("display", "display.log")
        )
        self._wait_connected(CONNECT_TIMEOUT_S + 3.0 * self.n)
        self._phase("processes_ready")
        if self.cfg.view:
            self._start_view()

    def _start_view(self) -> None:
        """--view: the live page (testbed.view.live), fed from the step loop's own records."""
        from testbed.view.live import KernelRoutes, LiveFeed, LiveServer, RobotEvents

        meta = {
            "run": os.path.basename(os.path.abspath(self.out)), "robots": self.n,
            "comm_range": self.cfg.comm_range, "map_m": list(self.truth.size_m),
            "display": list(self.display_pos), "status": "running", "steps": 0,
            "positions": [], "links": [], "coverage": [],
        }  # fmt: skip
        routes = KernelRoutes(self.net.name, self.n)
        self._stack.callback(routes.close)
        try:
            stats = []
            if self.cfg.routing == "aodv":
                from topology.routing import aodv_stats_file

                stats = [aodv_stats_file(k, self.net.state_dir) for k in range(1, self.n + 2)]
            events = RobotEvents(
                {k: self._path("robots", f"r{k}.events.jsonl") for k in range(1, self.n + 1)}
            )
            feed = LiveFeed(meta, routes, self.out, stats, events)
            self.live = LiveServer(feed, self.cfg.view, self.cfg.map)
        except OSError as e:
            raise TestbedError(
                f"--view {self.cfg.view}: cannot listen there: {e.strerror}"
            ) from None
        self._stack.callback(self.live.stop)
        print(f"live view: http://{self.live.host}:{self.live.port}/", file=sys.stderr)

    def _node_args(self, k: int, **role: object) -> NodeArgs:
        """What robot k's process is told: the run's parameters plus its role's own."""
        cfg, truth = self.cfg, self.truth
        return NodeArgs(
            robot=k, robots=self.n, body=self.server.path, map_size=truth.shape,
            cell=truth.cell, laser_range=cfg.laser_range, laser_rays=cfg.laser_rays,
            speed=cfg.speed, radius=cfg.radius, plan_period=cfg.plan_period,
            map_period=cfg.map_period, time_scale=cfg.time_scale, flood=cfg.flood,
            coordination=cfg.coordination, **role,
        )  # fmt: skip

    def _node_argv(self, k: int) -> list[str]:
        events = self._path("robots", f"r{k}.events.jsonl")
        return self._node_args(k, timer_phase=self.phases[k - 1], events=events).to_argv()

    def _display_argv(self) -> list[str]:
        return self._node_args(
            self.display_k, role="display", out_dir=self._path("display"),
            events=self._path("display", "events.jsonl"),
            snapshots=frozenset(self.cfg.snapshots or DEFAULT_SNAPSHOTS),
        ).to_argv()  # fmt: skip

    def _start_node(self, k: int, role: str, argv: list[str], log_path: str):
        """`python -m node ARGV` in robot k's namespace, forked from the fork server (the
        imports are already done there), recorded with the testbed so that teardown stops
        it."""
        with open(log_path, "w"):
            pass  # the child appends: the log starts empty
        proc = self.forks.spawn(
            self.net.robot_ns(k), "node.__main__", argv, log_path, title=f"r{k} {role}"
        )
        self.net.adopt(k, proc, role)
        return proc

    def _wait_connected(self, timeout: float) -> None:
        """Until every robot and the display said hello; TestbedError when one died first or
        the time ran out."""
        server, robots = self.server, self.robots
        deadline = time.monotonic() + timeout
        procs = [r.proc for r in robots.values()] + [self.display_proc]
        while time.monotonic() < deadline:
            server.wait_for(set(robots), {self.display_k}, timeout=0.2)
            if set(robots) <= set(server.robots) and self.display_k in server.displays:
                return
            if any(p.poll() is not None for p in procs):
                break
        missing = sorted(set(robots) - set(server.robots))
        if not missing and self.display_k in server.displays:
            return
        dead = [k for k in robots if robots[k].proc.poll() is not None]
        raise TestbedError(
            f"robot processes did not connect to the world: {missing or 'display'}"
            + (f" (r{dead[0]} exited with {robots[dead[0]].proc.returncode})" if dead else "")
        )

    # -- steps --------------------------------------------------------------------------------

    def _start_clock(self) -> None:
        """Step 0: the first frames go out and the schedule is anchored."""
        self.period = STEP_S / self.cfg.time_scale
        self.kills: dict[int, list[int]] = {}
        for k, s in self.cfg.kill:
            self.kills.setdefault(s, []).append(k)
        self.timing = StepTiming()
        self.stalls = StallTracker(self.period)
        self._tty = self.progress and sys.stderr.isatty()
        self._last_print = 0.0
        self.scans = [self.world.scan(i) for i in range(self.n)]
        self.cov_w.writerow([0, f"{self.world.coverage():.5f}"])
        self.pos_w.writerow([0] + [f"{v:.3f}" for p in self.world.positions() for v in p])
        self.status, self.detail = "step_cap", f"the step cap ({self.cfg.max_steps}) was reached"
        self._t0 = time.monotonic()
        self.anchor = self._t0  # step k's deadline is anchor + (k + 1) * period
        self._cpu0 = time.process_time()
        self._send_frames()

    def step(self) -> bool:
        """One step of the clock; False when the run is over (status and detail set)."""
        self._collect_commands(self.anchor + (self.step_no + 1) * self.period)
        self.step_no += 1
        step, t = self.step_no, self.timing
        tw = time.monotonic()
        self.world.move()
        self._update_links()
        self._inject_kills()
        self._notice_crashes()
        ts = time.monotonic()
        self.scans = [
            self.world.scan(i) if not self.robots[i + 1].crashed else None for i in range(self.n)
        ]
        cov = self.world.coverage()
        self.cov_w.writerow([step, f"{cov:.5f}"])
        if self.live is not None:
            missed = sum(r.missed for r in self.robots.values())
            achieved = round(step * STEP_S / max(1e-9, time.monotonic() - self._t0), 2)
            self.live.feed.publish(step, self._positions, self.net.current, cov, missed,
                                   achieved)  # fmt: skip
        tf = time.monotonic()
        t.scan_s += tf - ts
        self._send_frames()
        t.send_s += time.monotonic() - tf
        t.world_s += time.monotonic() - tw
        self._count_world_overrun()
        self._show_progress(cov)
        return not self._over()

    def _collect_commands(self, deadline: float) -> None:
        """Take the robots' commands until the step's deadline, then count who had not
        answered the step's frame by then."""
        while True:
            left = deadline - time.monotonic()
            for k, msg in self.server.poll(max(0.0, left)):
                if not 1 <= k <= self.n:
                    continue
                r = self.robots[k]
                if msg[0] == "cmd":
                    r.last_cmd = max(r.last_cmd, msg[1])
                    self.world.command(k - 1, msg[2])
                elif msg[0] == "done" and r.finish_step is None:
                    r.finish_step = self.step_no
            if left <= 0:
                break
        self.stalls.late(self.step_no, time.monotonic() - deadline)
        for r in self.robots.values():
            if not r.crashed and r.last_cmd < self.step_no:
                r.missed += 1
                self.stalls.count(self.step_no, 1)
                if len(r.missed_steps) < MAX_MISSED_STEPS_KEPT:
                    r.missed_steps.append(self.step_no)

    def _update_links(self) -> None:
        """The new positions to the topology controller; links.csv gets what changed."""
        tn = time.monotonic()
        positions = self._positions = self.world.positions()
        added, removed = self.net.set_positions(positions + [self.display_pos])
        spent = time.monotonic() - tn
        self.timing.net_s += spent
        self.timing.net_max_s = max(self.timing.net_max_s, spent)
        for i, j in sorted(removed):
            self.links_w.writerow([self.step_no, "remove", i, j])
        for i, j in sorted(added):
            self.links_w.writerow([self.step_no, "add", i, j])
        self.pos_w.writerow([self.step_no] + [f"{v:.3f}" for p in positions for v in p])

    def _inject_kills(self) -> None:
        for k in self.kills.get(self.step_no, []):
            r = self.robots[k]
            with contextlib.suppress(ProcessLookupError):
                os.kill(r.proc.pid, signal.SIGKILL)
            r.killed_at = self.step_no

    def _notice_crashes(self) -> None:
        for k, r in self.robots.items():
            if not r.crashed and r.proc.poll() is not None:
                r.crashed, r.crash_step, r.exit_status = True, self.step_no, r.proc.returncode
                self.world.bodies[k - 1].alive = False
                log.warning("r%d exited with status %s at step %d", k, r.exit_status, self.step_no)

    def _send_frames(self) -> None:
        now = time.monotonic()
        self.timing.clock.append(round(now, 4))
        for k, r in self.robots.items():
            if r.crashed:
                continue
            b = self.world.bodies[k - 1]
            self.server.send(k, body.frame(self.step_no, b.x, b.y, b.theta, self.scans[k - 1], now))
        x, y = self.display_pos
        self.server.send(self.display_k, body.frame(self.step_no, x, y, 0.0, None), True)

    def _count_world_overrun(self) -> None:
        late = time.monotonic() - (self.anchor + (self.step_no + 1) * self.period)
        if late <= 0:
            return
        # The world's own work ran past this step's deadline: count it once and move the
        # schedule (catching up by running steps back to back would squeeze the robots).
        self.missed_world += 1
        self.stalls.late(self.step_no, late)
        self.stalls.count(self.step_no, 1)
        self.anchor += late
        if len(self.timing.missed_steps) < MAX_MISSED_STEPS_KEPT:
            self.timing.missed_steps.append([self.step_no, round(late * 1000, 1)])

    def _show_progress(self, coverage: float) -> None:
        now = time.monotonic()
        if not self.progress or now - self._last_print <= (0.5 if self._tty else 10.0):
            return
        self._last_print = now
        live = [r for r in self.robots.values() if not r.crashed]
        done = sum(1 for r in live if r.finish_step is not None)
        scale = self.step_no * STEP_S / max(1e-9, now - self._t0)
        missed = self.missed_world + sum(r.missed for r in self.robots.values())
        line = (
            f"step {self.step_no}/{self.cfg.max_steps}  coverage {100 * coverage:5.1f}%  "
            f"finished {done}/{self.n}  crashed {self.n - len(live)}  scale {scale:.1f}x  "
            f"missed {missed}"
        )
        sys.stderr.write(("\r" + line + "  ") if self._tty else (line + "\n"))
        sys.stderr.flush()

    def _over(self) -> bool:
        live = [r for r in self.robots.values() if not r.crashed]
        if live and all(r.finish_step is not None for r in live):
            self.status, self.detail = "complete", f"all robots finished by step {self.step_no}"
            return True
        if not live:
            self.status, self.detail = "robot_crashed", "every robot process died"
            return True
        return self.step_no >= self.cfg.max_steps

    def _stop_clock(self) -> None:
        self.loop_wall_s = time.monotonic() - self._t0
        self.timing.world_cpu_s = time.process_time() - self._cpu0
        if self._tty:
            sys.stderr.write("\n")
        crashed = [r for r in self.robots.values() if r.crashed]
        if not crashed:
            return
        r = crashed[0]
        if self.status != "robot_crashed":
            self.status = "robot_crashed"
            self.detail = f"r{r.k} exited with status {r.exit_status} at step {r.crash_step}" + (
                f"; {len(crashed) - 1} more" if len(crashed) > 1 else ""
            )
        else:
            self.detail = (
                f"r{r.k} exited with status {r.exit_status} at step {r.crash_step}; all died"
            )

    # -- finish -------------------------------------------------------------------------------

    def _end_processes(self) -> None:
        """Tell everyone the run is over and give them a moment to write their logs."""
        for k, r in self.robots.items():
            if not r.crashed:
                self.server.send(k, body.END)
        self.server.send(self.display_k, body.END, True)
        deadline = time.monotonic() + END_GRACE_S
        live = [r.proc for r in self.robots.values() if not r.crashed] + [self.display_proc]
        for p in live:
            with contextlib.suppress(subprocess.TimeoutExpired):
                p.wait(timeout=max(0.1, deadline - time.monotonic()))
        for r in self.robots.values():
            if not r.crashed:
                r.exit_status = r.proc.poll()
        self._phase("processes_ended")

    def _keep_routing_files(self) -> None:
        """Stop the routing daemons (they write their final statistics and logs as they stop)
        and copy those into the run directory before the testbed goes away."""
        from topology.routing import keep_daemon_files

        routing = self.cfg.routing
        if routing not in ("none", "oracle"):  # oracle: no daemon (topology.oracle)
            self.net.stop(routing)
            keep_daemon_files(routing, range(1, self.n + 2), self.net.state_dir,
                              self._path("routing"), self._path(routing))  # fmt: skip
        self._phase("routing_stopped")

    def _write_clock(self) -> None:
        """clock.csv: when (CLOCK_MONOTONIC, the clock robots log receipts with) each step
        began; what lets testbed.analysis.runcheck place a receipt at the world's step."""
        with open(self._path("clock.csv"), "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["step", "t"])
            w.writerows(enumerate(self.timing.clock if self.timing else []))

    def finish(self) -> dict:
        """Write the per-robot records, paths.png and, last, result.json; returns the result."""
        from testbed import runresults

        t_results = time.monotonic()
        result = runresults.write(self)
        result["wall_parts_s"]["results"] = round(time.monotonic() - t_results, 3)
        write_json_atomic(self._path("result.json"), result)
        return result

    @property
    def total_wall_s(self) -> float:
        return time.monotonic() - self._t_start


if __name__ == "__main__":  # `python -m testbed.run` is `testbed run`
    from testbed.cli import main as cli_main

    sys.exit(cli_main(["run", *sys.argv[1:]]))
