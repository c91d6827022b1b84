"""What a network's bring-up starts besides the medium (topology.network.Network.up): the
checks made before touching the kernel, the namespaces, the packet captures and the routing
daemons.

Theory of operation. `preflight` checks privileges and tools before anything is made.
`create_namespace` makes one namespace and says so when its name is taken (a testbed left
behind: `testbed clean`). Once the robots' links are up, `start_captures` starts tcpdump per
robot (topology.kernel.capture) and waits until each one captures, and `start_routing`
starts the routing daemon per robot (topology.routing): forked from the network's fork server
for a daemon written in Python, else as a program in the robot's namespace; it returns only
once every daemon can route. Every process is recorded by the network (`spawn`, `adopt`), so
that teardown finds it.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import time
from typing import Any, Protocol

from common.errors import TestbedError, UsageError
from common.jsonfile import write_json_atomic
from topology import routing, state
from topology.kernel import capture, netns
from topology.kernel.forkserver import Forked, ForkServer, ForkServerError, python_env
from topology.spec import NetworkSpec


class Network(Protocol):
    """What bring-up asks of the network it starts processes for (topology.network.Network,
    which imports this module: bring-up names the part it uses rather than the class)."""

    spec: NetworkSpec

    @property
    def timers(self) -> Any: ...

    @property
    def state_dir(self) -> str: ...

    def robot_ns(self, k: int) -> str: ...

    def spawn(self, k: int, argv: list[str], *, role: str, **popen_kwargs) -> subprocess.Popen: ...

    def adopt(self, k: int, proc, role: str) -> None: ...


# The Debian/Ubuntu package of each tool preflight asks for (a routing daemon's: its entry in
# topology.protocols).
TOOL_PACKAGES = {"ip": "iproute2", "tcpdump": "tcpdump"}


def preflight(spec: NetworkSpec) -> None:
    """What can be checked before touching the kernel: privileges and tools."""
    if os.geteuid() != 0:
        raise UsageError("network namespaces need root: run this under sudo")
    missing = [t for t in ("ip",) if shutil.which(t) is None]
    if spec.capture_dir and shutil.which("tcpdump") is None:
        missing.append("tcpdump")
    missing += routing.missing_tools(spec.routing)
    if missing:
        packages = {**TOOL_PACKAGES, **routing.tool_packages(spec.routing)}
        pkgs = ", ".join(dict.fromkeys(packages.get(t, t) for t in missing))
        raise UsageError(
            f"missing tool(s): {', '.join(missing)} (package(s) {pkgs}: `sudo make setup` "
            "installs those the distribution has)"
        )
    why = routing.preflight_refusal(spec)
    if why:
        raise UsageError(why)


def routing_fork_server(spec: NetworkSpec) -> ForkServer | None:
    """The fork server of the routing daemon when it is written in Python (its imports run
    while the kernel objects are made), else None."""
    forkable = routing.forkable(spec)
    if forkable is None:
        return None
    return ForkServer(
        list(forkable.preload), env=python_env(),
        warm=[[m, f, list(a)] for m, f, a in forkable.warm],
        label=f"{spec.name} {spec.routing}",
    )  # fmt: skip


def create_namespace(ns: str) -> None:
    try:
        netns.create(ns)
    except FileExistsError:
        raise UsageError(f"namespace {ns} already exists (try `testbed clean`)") from None


def start_captures(net: Network) -> None:
    """tcpdump on every robot's wlan0, into the spec's capture directory, and the
    network's description next to them; returns once every capture is running."""
    cdir = net.spec.capture_dir
    assert cdir is not None  # called only with one
    os.makedirs(cdir, exist_ok=True)
    # What the captures are of (the routing protocol, for `testbed metrics`), next to the
    # daemons' logs that teardown keeps (topology.teardown._keep_logs).
    os.makedirs(os.path.join(cdir, "daemons"), exist_ok=True)
    about = state.spec_to_dict(net.spec)
    if net.timers is not None:
        about["network_timers"] = net.timers.to_dict()
    write_json_atomic(os.path.join(cdir, "daemons", "network.json"), about)
    started = []
    for k in net.spec.robot_ids():
        logp = os.path.join(net.state_dir, f"r{k}.tcpdump.log")
        with open(logp, "w") as logf:
            proc = net.spawn(k, capture.tcpdump_argv(cdir, k), role="tcpdump",
                             stdout=subprocess.DEVNULL, stderr=logf)  # fmt: skip
        started.append((logp, proc))
    for logp, proc in started:
        try:
            capture.wait_ready(logp, proc)
        except RuntimeError as exc:
            raise TestbedError(f"packet capture: {exc}") from None


def start_routing(net: Network, forks: ForkServer | None) -> None:
    """The routing daemon of every robot: forked from `forks` (the fork server of a daemon
    written in Python) or started as a program; returns once every one can route."""
    started = []
    forkable = routing.forkable(net.spec)
    for k in net.spec.robot_ids():
        argv = routing.argv_for(net.spec, k, net.state_dir)
        if argv is None:
            continue
        logp = routing.log_file(net.spec.routing, k, net.state_dir)
        proc: Forked | subprocess.Popen
        if forkable is not None and forks is not None:  # started iff forkable
            open(logp, "w").close()  # the child appends
            args = routing.fork_args(net.spec, k, net.state_dir)
            try:
                proc = forks.spawn(
                    net.robot_ns(k), forkable.module, args, logp,
                    title=f"r{k} {net.spec.routing}",
                )  # fmt: skip
            except ForkServerError as exc:
                raise TestbedError(f"{net.spec.routing} daemon of r{k}: {exc}") from None
            net.adopt(k, proc, net.spec.routing)
        else:
            with open(logp, "w") as logf:
                proc = net.spawn(k, argv, role=net.spec.routing, stdout=logf,
                                 stderr=subprocess.STDOUT)  # fmt: skip
        started.append((k, proc, logp))
    # Return only once every daemon can route, so the first packet is not lost to a race.
    deadline = time.monotonic() + routing.READY_TIMEOUT_S
    for k, proc, logp in started:
        ready = routing.ready_file(net.spec.routing, k, net.state_dir)
        while ready and not os.path.exists(ready):
            if proc.poll() is not None or time.monotonic() > deadline:
                with open(logp) as f:
                    last = (f.read().strip().splitlines() or ["(no output)"])[-1]
                what = "exited" if proc.poll() is not None else "did not start in time"
                raise TestbedError(f"{net.spec.routing} daemon of r{k} {what}: {last}")
            time.sleep(0.01)
