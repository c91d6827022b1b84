"""The routing choice, behind one small interface: what to run in each robot's namespace.

A routing protocol is an entry of topology.protocols' registry (its data: port, tools, files,
fork server) and, when it has a daemon, an argv per robot built by the function here that the
entry names. The Network starts it with the other per-robot processes, records its pid and
stops it at teardown; every table below is read from the registry, so adding a protocol is
its entry and its argv builder (docs/architecture.md, "Adding a routing protocol").

- none:  nothing; routes are the user's business (only direct neighbours on a /32 need none
         either: they still need a route, so with `none` even one hop needs `ip route add`).
- babel: Debian's babeld (RFC 8966), proactive, on wlan0 declared *wireless*: that turns off
         split horizon, which would be wrong on a medium where neighbours of a robot need not
         hear each other, and uses ETX link costs. Hello interval scales with the time scale.
- batman: Debian's batmand (B.A.T.M.A.N. III, layer 3, proactive). Its originator interval
         (-o, 1000 ms by default) is divided by the time scale; its other timers are fixed
         in the program and cannot be scaled (originator timeout 200 s, the TQ windows count
         packets). batmand is made for a mesh subnet: it sends its OGMs to the interface's
         broadcast address and routes through policy rules for the interface's network
         ("to NET lookup 66", "to NET lookup 67": unreachable). So a batman robot's wlan0
         carries 10.0.0.K/16 instead of /32 (inside its namespace); the subnet route the
         kernel adds to the main table is never reached, as batmand's rules come first and
         end in "unreachable" for a robot it has no route to, as with the other protocols.
         batmand has no option for its unix socket (/var/run/batmand.socket): each daemon
         runs in a private mount namespace with its own /run, so ten of them do not collide.
- oracle: no daemon and no control packet: the topology controller installs shortest-path
         routes in every robot the moment a link changes (topology.oracle), the baseline
         the real protocols are measured against.
- aodv:  this project's AODV daemon, on demand, with the parameter profile the spec names
         (`aodv_profile`: rfc or ns3) and a counter file in the run dir that makes a
         restarted daemon obey the RFC 6.13 reboot rule. Two programs with one command line
         and one statistics file: the spec's `aodv_daemon` says which runs, `python` (python
         -m aodv, the reference) or `cpp` (build/tb-aodv, native/aodv/daemon, built by
         `make setup`; exec'd in the namespace like babeld). testbed.run.daemonchoice turns a
         run's `--aodv-daemon auto|cpp|python` into one of the two; `preflight_refusal` says,
         before anything is made, when the compiled one was asked for and is not there.

A daemon written in Python (aodv's Python daemon) is also *forkable*: the Network starts it
from a fork server (topology.kernel.forkserver) that has imported the daemon and warmed it up
once, instead of one interpreter per robot. Starting 11 daemons as interpreters took 1.1-1.2 s
of wall time on two cores (about 0.2 s of CPU each for start-up and imports); from the fork
server, started at the beginning of the network's bring-up, 0.34-0.49 s.
"""

import os
import shutil
import sys
from collections.abc import Callable, Iterable
from pathlib import Path

from common.paths import PROJECT_ROOT
from topology import names
from topology.kernel import netns
from topology.protocols import REGISTRY, Forkable, Protocol

BABEL_HELLO_S = 1.0  # babeld's wireless default is 4 s; 1 s converges a 5-hop chain in ~5 s


def babel_argv(k: int, run_dir: str, spec) -> list[str]:
    hello = max(0.05, BABEL_HELLO_S / spec.time_scale)
    return [
        "babeld",
        "-I", f"{run_dir}/r{k}.babeld.pid",
        "-S", f"{run_dir}/r{k}.babeld.state",
        "-C", f"interface {names.ROBOT_IFACE} type wireless hello-interval {hello:.2f}",
        "-C", f"redistribute local ip {names.NETWORK} ge 32 allow",
        "-C", "redistribute local deny",
        names.ROBOT_IFACE,
    ]  # fmt: skip


BATMAN_OGM_MS = 1000  # batmand's default originator interval


def batman_argv(k: int, run_dir: str, spec) -> list[str]:
    ogm_ms = max(10, round(BATMAN_OGM_MS / spec.time_scale))
    addr = names.robot_addr(k)
    dev = names.ROBOT_IFACE
    prefix = names.NETWORK.split("/")[1]
    setup = (
        f"mount -t tmpfs batman-run /run && "
        f"ip addr del {addr}/32 dev {dev} && "
        f"ip addr add {addr}/{prefix} broadcast + dev {dev} && "
        f"exec batmand --no-detach -d 0 -o {ogm_ms} {dev}"
    )
    return ["unshare", "--mount", "--propagation", "private", "sh", "-c", setup]


def log_file(routing: str, k: int, run_dir: str) -> str:
    """Where robot k's daemon writes its log (stdout and stderr), in the testbed's run dir."""
    return os.path.join(run_dir, f"r{k}.{routing}.log")


def aodv_stats_file(k: int, run_dir: str) -> str:
    """Where robot k's AODV daemon writes its statistics (aodv/stats.py)."""
    stats = stats_file("aodv", k, run_dir)
    assert stats is not None  # the registry's aodv entry names it
    return stats


def aodv_state_file(k: int, run_dir: str) -> str:
    """Robot k's AODV counter file (aodv/persist.py): lives as long as the network."""
    return os.path.join(run_dir, f"r{k}.aodv.state")


def aodv_args(k: int, run_dir: str, spec) -> list[str]:
    return [
        "--robot", f"r{k}",
        "--iface", names.ROBOT_IFACE,
        "--time-scale", repr(spec.time_scale),
        "--profile", spec.aodv_profile,
        "--stats", aodv_stats_file(k, run_dir),
        "--stats-period", repr(float(spec.aodv_stats_period)),
        "--state", aodv_state_file(k, run_dir),
    ]  # fmt: skip


# The compiled AODV daemon (native/aodv/daemon), and make setup's one line where it could not
# build it. TESTBED_TB_AODV in the environment names another build of the same program (a
# sanitizer's, say).
TB_AODV = Path(PROJECT_ROOT) / "build" / "tb-aodv"
TB_AODV_UNBUILT = TB_AODV.with_name("tb-aodv.unbuilt")
TB_AODV_ENV = "TESTBED_TB_AODV"


def aodv_binary() -> str:
    """The compiled AODV daemon's path: TESTBED_TB_AODV, else build/tb-aodv."""
    return os.environ.get(TB_AODV_ENV) or str(TB_AODV)


def aodv_built() -> bool:
    """Whether the compiled AODV daemon is there to run."""
    path = aodv_binary()
    return os.path.isfile(path) and os.access(path, os.X_OK)


def aodv_unbuilt_reason() -> str | None:
    """Why build/tb-aodv is not here: make setup's one line where it could not build it, or
    None (also where neither the program nor that line is there: setup has not run, and what
    needs the program fails rather than skipping in silence)."""
    if aodv_built():
        return None
    try:
        with open(TB_AODV_UNBUILT) as f:
            return f.readline(500).strip() or None
    except OSError:
        return None


def aodv_command(daemon: str = "python") -> list[str]:
    """The AODV daemon's program, before its arguments (aodv_args): `python -m aodv` or the
    compiled daemon; both take the same arguments and write the same statistics file."""
    if daemon == "cpp":
        return [aodv_binary()]
    return [sys.executable, "-m", "aodv"]


def aodv_argv(k: int, run_dir: str, spec) -> list[str]:
    """The compiled daemon enters robot k's namespace itself (--netns, before any socket), so
    it starts without `ip netns exec` (3.7 of the 8.3 s of starting 1,000 daemons); the
    Python daemon is forked from a fork server that enters it (`forkable`)."""
    if spec.aodv_daemon == "cpp":
        ns = names.robot_ns(spec.name, k)
        return netns.EnteringArgv(ns, aodv_binary(), aodv_args(k, run_dir, spec))
    return [*aodv_command(spec.aodv_daemon), *aodv_args(k, run_dir, spec)]


# (robot number, the testbed's run dir, the NetworkSpec) -> argv
ArgvBuilder = Callable[[int, str, object], list[str]]


def _builder(p: Protocol, name: str) -> ArgvBuilder:
    """The function of this module an entry of the registry names; a name that is not here
    fails at import."""
    f = globals().get(name)
    if not callable(f):
        raise ImportError(
            f"routing protocol {p.name!r} names {name!r}, not a function of {__name__}"
        )
    return f


# Each protocol's argv builder (None: no daemon), from the registry.
PROTOCOLS: dict[str, ArgvBuilder | None] = {
    p.name: _builder(p, p.daemon.argv) if p.daemon else None for p in REGISTRY.values()
}
# The arguments of each forkable daemon (its Forkable.args), from the registry.
FORK_ARGS: dict[str, ArgvBuilder] = {
    p.name: _builder(p, p.daemon.forkable.args)
    for p in REGISTRY.values()
    if p.daemon and p.daemon.forkable
}
FORKABLE: dict[str, Forkable] = {
    p.name: p.daemon.forkable for p in REGISTRY.values() if p.daemon and p.daemon.forkable
}
REQUIRED_TOOLS: dict[str, list[str]] = {
    p.name: list(p.daemon.tools) if p.daemon else [] for p in REGISTRY.values()
}
READY_TIMEOUT_S = 30.0


def has_daemon(routing: str) -> bool:
    """Whether the protocol runs a daemon in each robot's namespace (none and the oracle do not)."""
    return REGISTRY[routing].daemon is not None


def tool_packages(routing: str) -> dict[str, str]:
    """The Debian package of each program the protocol's daemon needs."""
    daemon = REGISTRY[routing].daemon
    return dict(daemon.tools) if daemon else {}


def _run_file(pattern: str | None, k: int, run_dir: str) -> str | None:
    return os.path.join(run_dir, pattern.format(k=k)) if pattern else None


def stats_file(routing: str, k: int, run_dir: str) -> str | None:
    """Where robot k's daemon writes its statistics, or None: the protocol's daemons write none."""
    daemon = REGISTRY[routing].daemon
    return _run_file(daemon.stats_file if daemon else None, k, run_dir)


def forkable(spec) -> Forkable | None:
    """How to fork the spec's routing daemon from a fork server, or None: it is a program
    (babeld, batmand, the compiled AODV daemon), started as such."""
    if spec.routing == "aodv" and spec.aodv_daemon == "cpp":
        return None
    return FORKABLE.get(spec.routing)


def preflight_refusal(spec) -> str | None:
    """Why the spec's routing daemon cannot start on this machine, in one line, or None;
    asked before anything is made (the tools babeld and batmand need: missing_tools)."""
    if spec.routing != "aodv" or spec.aodv_daemon != "cpp" or aodv_built():
        return None
    why = aodv_unbuilt_reason() or "make setup builds it where g++ is"
    return f"the compiled AODV daemon {aodv_binary()} is not there: {why}"


def ready_file(routing: str, k: int, run_dir: str) -> str | None:
    """A file whose appearance says robot k's daemon is up, or None: nothing to wait for."""
    daemon = REGISTRY[routing].daemon
    return _run_file(daemon.ready_file if daemon else None, k, run_dir)


def missing_tools(routing: str) -> list[str]:
    return [t for t in REQUIRED_TOOLS.get(routing, []) if shutil.which(t) is None]


def keep_daemon_files(
    routing: str, robots: Iterable[int], run_dir: str, logs_dir: str, stats_dir: str | None
) -> None:
    """Copy what each robot's routing daemon left in the testbed's run dir: its log into
    `logs_dir` (same name, rK.<routing>.log) and its statistics, for a protocol whose daemons
    write any, into `stats_dir` as rK.json. Files a daemon did not write are skipped."""
    if stats_file(routing, 0, run_dir) is None:
        stats_dir = None  # its daemons write none
    for d in (logs_dir, stats_dir):
        if d:
            os.makedirs(d, exist_ok=True)
    for k in robots:
        src = log_file(routing, k, run_dir)
        if os.path.exists(src):
            shutil.copy(src, os.path.join(logs_dir, os.path.basename(src)))
        stats = stats_file(routing, k, run_dir)
        if stats and stats_dir and os.path.exists(stats):
            shutil.copy(stats, os.path.join(stats_dir, f"r{k}.json"))


def fork_args(spec, k: int, run_dir: str) -> list[str]:
    """Robot k's daemon arguments when it is forked (forkable(spec) is not None)."""
    return FORK_ARGS[spec.routing](k, run_dir, spec)


def argv_for(spec, k: int, run_dir: str) -> list[str] | None:
    """Robot k's daemon command line for the spec's routing, or None (no daemon)."""
    builder = PROTOCOLS[spec.routing]
    return builder(k, run_dir, spec) if builder else None
