"""One run: `testbed run --robots N --comm-range R --laser-range L --seed S --out DIR ...`.

Theory of operation. A run goes through four stages, each producing the value the next one
takes:

- `prepare()` (testbed.run.prepare) builds the world and the description of the testbed
  network, checks that this machine can do the run and that DIR may be written, makes the
  directory and writes config.json. It returns a frozen `PreparedRun`.
- `Run.start()` brings the network up, starts `python -m node` in every namespace (forked
  from a fork server that imported the node package and built the laser's tables once, so a
  dozen processes are ready in a fraction of a second instead of each paying for numpy),
  waits until each has connected to the world's body link (a Unix socket, off the emulated
  network) and returns the frozen `Started` (network, body server, open files, processes).
- `StepLoop` (testbed.run.steploop) runs the steps. Each is one tick of the clock
  (testbed.run.stepclock: 100 ms of emulated time, `time_scale` times faster in wall time):
  it collects the robots' commands until the step's deadline, moves each robot toward the
  target its process last commanded, feeds all positions to the topology controller (links
  follow before the step goes on), casts the lasers and sends each robot its frame (step,
  pose, scan) and the display its clock. The loop runs at real-time priority (SCHED_RR
  2): it is the clock, and a robot woken by its frame must not preempt the world before the
  other robots' frames are out. It returns the run's status.
- `Run.finish()` freezes what the run saw into a `RunRecord` (testbed.run.record), from
  which testbed.run.results writes robots/rK.json, paths.png and, last, result.json.

With `--start-when FILE` (a sweep's pre-started run, testbed.sweep.runner) the run waits
between `start()` and the step loop, its processes connected and idle, until FILE exists
(looked for every GATE_POLL_S): its step clock starts then, so its deadlines and fidelity
mean what they do in any run, and wall_parts_s.gate_wait records the wait. When FILE is
not there after `--start-timeout` seconds, the run ends with status `gate_timeout`; SIGINT
while it waits tears it down as at any other time.

`Run.execute()` starts, steps and finishes, and turns a failure into a recorded status:
whatever happens after `prepare()`, result.json is written (docs/run-results.md: config.json
first, result.json last, atomically), and the network is torn down (the ExitStack that
`start()` filled: routing logs kept, network down, servers and files closed).

The clock counts every missed deadline, the world's (its own work overran) and each robot's
(it had not answered the step's frame by the deadline); `deadline_miss_fraction` is misses
over steps x (robots + 1). The run ends when every robot that is still in it has finished
(no reachable frontier on its own map), or at the step cap. A robot process that dies
unasked before the end is recorded with its exit status and step (status `robot_crashed`);
one the run kills on purpose (`--kill`) is *stopped*: the others carry on and decide the
status, and the averages over robots leave it out (testbed.run.record). `--isolate` takes a
robot's radio out of range for a window of steps (testbed.files.isolation): the step loop tells
the topology controller which robots are out before it feeds the step's positions. See
docs/architecture.md for the process tree.

No object of this module or of testbed.run.steploop changes its own attributes after
`__init__`: what changes during a run lives in the clock, the robots' records, the timing
counters and the files, each a class of its own module (a unit test holds this).
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import secrets
import subprocess
import sys
import time
from typing import TYPE_CHECKING, Any

from common.errors import TestbedError, UsageError
from common.jsonfile import write_json_atomic
from common.sched import CLOCK_PRIORITY, deadline_priority
from node import body, messaging
from node.launch import NodeArgs, run_params
from node.messaging.maps import MODULES as MAP_TOPIC_MODULES
from testbed.files import layout
from testbed.files.configfile import RunConfigFile
from testbed.files.resultfile import RunResult
from testbed.files.runconfig import RunConfig
from testbed.run import daemonchoice, robotchoice
from testbed.run import results as runresults
from testbed.run.arguments import add_arguments, config_from_args
from testbed.run.files import RunFiles
from testbed.run.prepare import DEFAULT_SNAPSHOTS, PreparedRun, prepare
from testbed.run.progress import summary_line
from testbed.run.record import RobotRecord, RunRecord, WallParts
from testbed.run.started import Started
from testbed.run.stepclock import no_clock
from testbed.run.steploop import StepLoop, loop_kind
from testbed.world.bodylink import BodyServer
from topology.kernel import neightable
from topology.kernel.forkserver import Forked, ForkServer, ForkServerError, python_env

if TYPE_CHECKING:  # imported where they are needed: the view's web server is not light
    from testbed.view.live import LiveServer
    from topology.network import Network

log = logging.getLogger(__name__)

# What the fork server imports once for every robot and the display (topology.kernel.forkserver);
# the run's middleware module (node.messaging) is added to it.
NODE_PRELOAD = [
    "node.__main__",
    "node.robot",
    "node.display",
    "node.native",
    "node.nativedisplay",
    "topology.names",
]
CONNECT_TIMEOUT_S = 60.0  # plus 3 s per robot: every process must have said hello by then
END_GRACE_S = 15.0  # for the processes to write their logs after END
GATE_POLL_S = 0.003  # how often a run at its start gate looks for the gate's file
GATE_TIMEOUT = "gate_timeout"  # the status of a run whose start gate stayed shut
__all__ = [
    "DEFAULT_SNAPSHOTS", "PreparedRun", "Run", "RunConfig", "add_arguments",
    "main", "prepare", "run",
]  # fmt: skip


def main(args: argparse.Namespace) -> int:
    """`testbed run`: 0 when the run completed, 130 when it was interrupted (SIGINT or
    SIGTERM), 1 when it ended badly otherwise (see result.json)."""
    cfg = config_from_args(args)
    name = args.name or "run" + secrets.token_hex(2)
    replace = getattr(args, "replace", False)
    gate = getattr(args, "start_when", None)
    result = run(cfg, args.out, name, progress=not args.quiet, replace=replace,
                 steps_over=getattr(args, "steps_over", None),
                 gate=None if gate is None else (gate, args.start_timeout))  # fmt: skip
    print(summary_line(result, args.out), flush=True)
    for line in (fidelity_warning(result), network_note(result)):
        if line:
            sys.stderr.write(line + "\n")
    if result.status != "complete":
        sys.stderr.write(f"testbed run: {result.status}: {result.status_detail}\n")
        return 130 if result.status == "interrupted" else 1
    return 0


def fidelity_warning(result: RunResult) -> str | None:
    """The one line `testbed run` prints for a run its verdict (testbed.run.fidelity) found
    unfaithful to the time scale; None for a faithful one."""
    if result.faithful is not False:
        return None
    return (
        f"testbed run: warning: not faithful at time scale {result.time_scale_requested:g}: "
        f"{result.fidelity_reason}; its results may differ from a slower run's (a lower "
        "--time-scale)"
    )


def network_note(result: RunResult) -> str | None:
    """The one line `testbed run` prints for a dilated run whose TCP could not be dilated
    (testbed.run.fidelity.network_verdict); None otherwise."""
    if result.network_faithful is not False:
        return None
    return (
        f"testbed run: note: {result.network_reason}; compare its PDF and delay only with "
        f"runs at time scale {result.time_scale_requested:g}"
    )


def run(
    cfg: RunConfig,
    out: str,
    name: str,
    progress: bool = True,
    replace: bool = False,
    cpp_robots: frozenset[int] | None = None,
    steps_over: str | None = None,
    gate: tuple[str, float] | None = None,
) -> RunResult:
    """Do one run into directory `out`; returns its RunResult (also in out/result.json).
    UsageError, before anything is made, for a run that cannot be done or a directory that
    holds a run (unless `replace`). `cpp_robots` (tests of the robots' contract): a mixed
    team, those robots the C++ robot and the others the Python robot, whatever cfg.robot.
    `steps_over`: a file created when the last step is done (`Run.execute`); `gate`:
    (file, timeout s), the steps start once that file exists (the module docstring)."""
    prepared = prepare(cfg, out, name, replace)
    return runresults.write(Run(prepared, progress, cpp_robots, steps_over, gate).execute())


class GateTimeout(TestbedError):
    """The start gate (--start-when) stayed shut for --start-timeout seconds."""


class Run:
    """One prepared run: `execute()` starts it, steps it and returns its record."""

    def __init__(
        self,
        prepared: PreparedRun,
        progress: bool = True,
        cpp_robots: frozenset[int] | None = None,
        steps_over: str | None = None,
        gate: tuple[str, float] | None = None,
    ) -> None:
        self.prep = prepared
        self.steps_over = steps_over
        self.gate = gate
        self.cfg = prepared.cfg
        self.n = prepared.robots
        self.progress = progress
        self.robots = {k: RobotRecord(k) for k in range(1, self.n + 1)}
        self.parts = WallParts(time.monotonic())  # wall seconds of each stage
        # Which robot program runs and why (testbed.run.robotchoice); the display runs the
        # robots' program (the C++ one with C++ robots: node.native), Python in a mixed team.
        try:
            self.robot_impl, self.robot_reason = robotchoice.choose(
                self.cfg.robot, self.cfg.middleware, self.cfg.maps
            )
        except ValueError as e:
            raise UsageError(str(e)) from None
        self.cpp = {k for k in self.robots if self.robot_impl == "cpp"}
        if cpp_robots is not None:
            self.cpp = set(cpp_robots) & set(self.robots)
            names = ", ".join(f"r{k}" for k in sorted(self.cpp)) or "none"
            self.robot_impl = "mixed"
            self.robot_reason = f"mixed: C++ robots {names}, the others Python"
        loop_kind()  # TESTBED_STEP_LOOP refused here, before the network is up, not at step 0
        # Which AODV daemon runs and why (testbed.run.daemonchoice): the spec's, which the
        # same choice made (testbed.run.arguments.network_fields).
        try:
            daemon, self.aodv_daemon_reason = daemonchoice.choose(
                self.cfg.aodv_daemon, self.cfg.routing
            )
        except ValueError as e:
            raise UsageError(str(e)) from None
        self.aodv_daemon = prepared.spec.aodv_daemon if daemon else None

    # -- the whole run ------------------------------------------------------------------------

    def execute(self) -> RunRecord:
        """start, step until the end, finish; a failure becomes the run's status."""
        status = ("error", "the run did not start")
        loop: StepLoop | None = None
        priority = None
        network_timers = None
        table_fulls = None
        try:
            with contextlib.ExitStack() as stack:  # routing logs kept, network down, closed
                started = self.start(stack)
                network_timers = started.network_timers
                self._wait_at_gate()
                fulls_before = neightable.table_fulls()
                with deadline_priority(*CLOCK_PRIORITY) as priority:
                    loop = StepLoop(self.prep, started, self.robots, self.progress)
                    status = loop.run()
                fulls_after = neightable.table_fulls()
                if fulls_before is not None and fulls_after is not None:
                    table_fulls = fulls_after - fulls_before
                self.parts.mark("steps")
                # Of those, the wait for the robots' first answers (steploop's warm-up).
                self.parts.parts["steps_warmup"] = round(loop.clock.warmup_s, 3)
                self._say_steps_over()
                self._end_processes(started)
            self.parts.mark("network_down")
        except GateTimeout as e:
            status = (GATE_TIMEOUT, str(e))
        except (TestbedError, ForkServerError) as e:
            status = ("error", str(e).splitlines()[0] if str(e) else type(e).__name__)
            log.info("run failed: %s", status[1])  # `testbed run` prints the status
        except KeyboardInterrupt:
            status = ("interrupted", "interrupted (SIGINT or SIGTERM) before the end")
        return self.finish(status, loop, priority, network_timers, table_fulls)

    # -- start --------------------------------------------------------------------------------

    def _wait_at_gate(self) -> None:
        """--start-when FILE: set up and idle until FILE exists (the step clock is not
        started yet); GateTimeout after --start-timeout seconds."""
        if self.gate is None:
            return
        path, timeout = self.gate
        log.info("at the start gate: waiting for %s", path)  # -v: tests wait for this line
        deadline = time.monotonic() + timeout
        while not os.path.exists(path):
            if time.monotonic() > deadline:
                raise GateTimeout(f"the start gate {path} stayed shut for {timeout:g} s")
            time.sleep(GATE_POLL_S)
        self.parts.mark("gate_wait")

    def start(self, stack: contextlib.ExitStack) -> Started:
        """The network up and every robot process connected to its body, or TestbedError;
        what is started is pushed on `stack`, which takes it down in reverse."""
        from topology.network import Network

        prep = self.prep
        files = stack.enter_context(RunFiles(prep.out, self.n))
        env = python_env()
        env["OPENBLAS_NUM_THREADS"] = "1"  # a robot's numpy needs no thread pool of its own
        # Started first, so that its imports overlap the network's bring-up.
        laser = [self.cfg.laser_range, self.cfg.laser_rays, prep.truth.cell]
        preload = [*NODE_PRELOAD, messaging.module_of(self.cfg.middleware)]
        if self.cfg.maps == "pubsub":
            preload.append(MAP_TOPIC_MODULES[self.cfg.middleware])
        # The laser's tables are built once here for the Python robots forked from this
        # server (~0.2 s); the C++ robot builds its own and the display casts no laser.
        python_robots = any(k not in self.cpp for k in self.robots)
        warm = [["node.rays", "warm", laser]] if python_robots else []
        forks = ForkServer(preload, env=env, label=prep.out, warm=warm)
        stack.callback(forks.close)
        net = stack.enter_context(Network(prep.spec))
        # Runs before the network goes down: the daemons' last words are kept.
        stack.callback(self._keep_routing_files, net)
        self.parts.mark("network_up")
        server = BodyServer(os.path.join(net.state_dir, "body.sock"))
        stack.callback(server.close)
        files.links(0, net.links())

        def spawn(k: int, role: str, args: NodeArgs, log_path: str) -> Forked:
            with open(log_path, "w"):
                pass  # the child appends: the log starts empty
            title = f"r{k} {role}"
            # node.native replaces the forked child with build/tb-robot, the same argv;
            # node.nativedisplay runs it as a child, then draws what it kept.
            module = "node.__main__"
            if role == "robot" and k in self.cpp:
                module = "node.native"
            elif role == "display" and self.robot_impl == "cpp":
                module = "node.nativedisplay"
            proc = forks.spawn(net.robot_ns(k), module, args.to_argv(),
                               log_path, title=title)  # fmt: skip
            net.adopt(k, proc, role)  # recorded with the testbed: teardown stops it
            return proc

        for k, r in self.robots.items():
            events = layout.robot_events(prep.out, k)
            args = self._node_args(k, server, timer_phase=prep.phases[k - 1], events=events)
            r.proc = spawn(k, "robot", args, prep.path("robots", f"r{k}.log"))
        display = spawn(prep.display_k, "display", self._display_args(server),
                        prep.path("display", "display.log"))  # fmt: skip
        self._wait_connected(server, display, CONNECT_TIMEOUT_S + 3.0 * self.n)
        self.parts.mark("processes_ready")
        live = self._start_view(stack, net) if self.cfg.view else None
        return Started(net, server, files, display, live)

    def _start_view(self, stack: contextlib.ExitStack, net: Network) -> LiveServer:
        """--view: the live page (testbed.view.live), fed from the step loop's own records."""
        from testbed.view.live import KernelRoutes, LiveFeed, LiveServer, RobotEvents

        prep = self.prep
        meta = {
            "run": os.path.basename(prep.out), "robots": self.n,
            "comm_range": self.cfg.comm_range, "map_m": list(prep.truth.size_m),
            "display": list(prep.display_pos), "status": "running", "steps": 0,
            "positions": [], "links": [], "coverage": [],
        }  # fmt: skip
        routes = KernelRoutes(net.name, self.n)
        stack.callback(routes.close)
        try:
            from topology.routing import stats_file

            files = (stats_file(self.cfg.routing, k, net.state_dir) for k in range(1, self.n + 2))
            stats = [f for f in files if f]  # its daemons' statistics (topology.protocols)
            events = RobotEvents(
                {k: layout.robot_events(prep.out, k) for k in range(1, self.n + 1)}
            )
            feed = LiveFeed(meta, routes, prep.out, stats, events)
            assert self.cfg.view is not None  # called only with --view
            live = LiveServer(feed, self.cfg.view, self.cfg.map)
        except OSError as e:
            raise TestbedError(
                f"--view {self.cfg.view}: cannot listen there: {e.strerror}"
            ) from None
        stack.callback(live.stop)
        print(f"live view: http://{live.host}:{live.port}/", file=sys.stderr)
        return live

    def _node_args(self, k: int, server: BodyServer, **role: Any) -> NodeArgs:
        """What robot k's process is told: the run's parameters plus its role's own."""
        cfg, truth = self.cfg, self.prep.truth
        passed = {name: getattr(cfg, name) for name in run_params()}  # same names both sides
        return NodeArgs(robot=k, robots=self.n, body=server.path, map_size=truth.shape,
                        cell=truth.cell, **passed, **role)  # fmt: skip

    def _display_args(self, server: BodyServer) -> NodeArgs:
        prep = self.prep
        return self._node_args(
            prep.display_k, server, role="display", out_dir=prep.path("display"),
            events=layout.display_events(prep.out), snapshots=frozenset(prep.snapshots),
        )  # fmt: skip

    def _wait_connected(self, server: BodyServer, display: Forked, timeout: float) -> None:
        """Until every robot and the display said hello; TestbedError when one died first or
        the time ran out."""
        robots, display_k = self.robots, self.prep.display_k
        deadline = time.monotonic() + timeout
        procs = [r.process for r in robots.values()] + [display]
        while time.monotonic() < deadline:
            server.wait_for(set(robots), {display_k}, timeout=0.2)
            if set(robots) <= set(server.robots) and display_k in server.displays:
                return
            if any(p.poll() is not None for p in procs):
                break
        missing = sorted(set(robots) - set(server.robots))
        if not missing and display_k in server.displays:
            return
        dead = [k for k in robots if robots[k].process.poll() is not None]
        raise TestbedError(
            f"robot processes did not connect to the world: {missing or 'display'}"
            + (f" (r{dead[0]} exited with {robots[dead[0]].process.returncode})" if dead else "")
        )

    # -- finish -------------------------------------------------------------------------------

    def _say_steps_over(self) -> None:
        """--steps-over FILE: the steps are done and what is left (the processes' exit, the
        routing files, the network's teardown, the results) needs no deadline, so a sweep may
        start its next run beside it (testbed.sweep.runner). A file that cannot be made only
        costs that overlap."""
        if self.steps_over is None:
            return
        try:
            with open(self.steps_over, "x"):
                pass
        except OSError as e:
            log.warning("--steps-over %s: cannot create it: %s", self.steps_over, e.strerror)

    def _end_processes(self, started: Started) -> None:
        """Tell everyone the run is over and give them a moment to write their logs."""
        server = started.server
        for k, r in self.robots.items():
            if not r.gone:
                server.send(k, body.END)
        server.send(self.prep.display_k, body.END, True)
        deadline = time.monotonic() + END_GRACE_S
        live = [r.process for r in self.robots.values() if not r.gone] + [started.display_proc]
        for p in live:
            with contextlib.suppress(subprocess.TimeoutExpired):
                p.wait(timeout=max(0.1, deadline - time.monotonic()))
        for r in self.robots.values():
            if not r.crashed:
                r.exit_status = r.process.poll()
        self.parts.mark("processes_ended")

    def _keep_routing_files(self, net) -> None:
        """Stop the routing daemons (they write their final statistics and logs as they stop)
        and copy those into the run directory before the testbed goes away."""
        from topology.routing import has_daemon, keep_daemon_files

        routing = self.cfg.routing
        if has_daemon(routing):  # none and the oracle run none (topology.protocols)
            net.stop(routing)
            keep_daemon_files(routing, range(1, self.n + 2), net.state_dir,
                              self.prep.path("routing"), self.prep.path(routing))  # fmt: skip
        self.parts.mark("routing_stopped")
        counters = getattr(net.medium, "counters", None)  # the ns3-wifi channel's, if any
        if counters is not None:
            write_json_atomic(layout.medium_path(self.prep.out), counters())
            from topology.radio.ns3wifi import LAG_FILE

            # Each frame's relay lag, which the analysis takes out of the delays.
            net.medium.keep_lag_file(self.prep.path(LAG_FILE))

    def finish(
        self,
        status: tuple[str, str],
        loop: StepLoop | None,
        priority,
        network_timers=None,
        table_fulls: int | None = None,
    ) -> RunRecord:
        """The run's frozen record, for testbed.run.results to write."""
        return RunRecord(
            out=self.prep.out, config=RunConfigFile.from_dict(self.prep.config),
            time_scale=self.cfg.time_scale,
            status=status[0], detail=status[1], world=self.prep.world,
            robots=tuple(r.outcome() for r in self.robots.values()),
            clock=loop.clock.summary() if loop else no_clock(self.n),
            world_timing=loop.timing.seconds() if loop else {},
            parts=dict(self.parts.parts), priority=priority, t_start=self.parts.t_start,
            network_timers=network_timers, outages=self.cfg.isolate,
            robot=self.robot_impl, robot_reason=self.robot_reason,
            aodv_daemon=self.aodv_daemon, aodv_daemon_reason=self.aodv_daemon_reason,
            neighbour_table_fulls=table_fulls,
        )  # fmt: skip


if __name__ == "__main__":  # `python -m testbed.run.execute` is `testbed run`
    from testbed.cli import main as cli_main

    sys.exit(cli_main(["run", *sys.argv[1:]]))
