"""The routing protocols a network may run: one registry, one entry per protocol.

Theory of operation. A protocol is a frozen `Protocol` in `REGISTRY`, and everything the
testbed knows of it by name is read from that entry: the choices of `--routing` and the
spec's check (topology.spec.ROUTINGS, in the registry's order, the first the default), how
its daemon is started and what it needs and leaves (topology.routing: the argv builder it
names, the tools preflight asks for, the file that says it is up, its statistics, the fork
server for a daemon written in Python), which daemons a run stops and keeps the files of
(testbed.run.execute), the UDP port its control traffic is counted on in the captures
(testbed.analysis.framecounts.CONTROL_PORTS) and whether the protocols study counts it as
proactive (testbed.analysis.protocols.PROACTIVE). Adding a protocol is one entry here and,
for one with a daemon, the function in topology.routing that builds its command line.

This module is data only (it imports nothing but dataclasses), so the analysis, which must
not import what runs a testbed, reads it too; the behaviour (argv builders, file copying,
tool lookups) is topology.routing's. An entry is checked as it is made: a protocol without
its control port, or with a daemon that names no command line, fails at import, not later
in silence (the captures would have counted its overhead on AODV's port).
"""

from __future__ import annotations

from dataclasses import dataclass, field

# AODV's UDP port (RFC 3561, section 11): also where the captures of a protocol that sends no
# control traffic are watched, to show that nothing is there.
AODV_PORT = 654


@dataclass(frozen=True)
class Forkable:
    """A daemon that is a Python module with main(argv): how to fork it from a fork server
    (topology.kernel.forkserver) instead of starting one interpreter per robot."""

    module: str  # whose main(args) runs the daemon
    args: str  # the function of topology.routing giving its arguments (argv without -m)
    preload: tuple[str, ...]  # what the server imports for every daemon
    warm: tuple[tuple[str, str, tuple], ...]  # (module, function, args) the server calls once


@dataclass(frozen=True)
class Daemon:
    """The program each robot's namespace runs for a protocol."""

    # The function of topology.routing that builds robot k's command line:
    # (k, the testbed's run dir, the NetworkSpec) -> argv.
    argv: str
    # The programs it needs on PATH, each with the Debian package that has it (what preflight
    # names; the packages are in the Makefile's APT_PACKAGES, a unit test holds that).
    tools: dict[str, str] = field(default_factory=dict)
    # The names its processes run under (`comm`), for what measures their CPU (testbed.bench).
    programs: tuple[str, ...] = ()
    # A file in the run dir whose appearance says robot k's daemon is up ("{k}" is the robot);
    # None: it says nothing that can be waited for.
    ready_file: str | None = None
    # The statistics file robot k's daemon writes, kept in a run as ROUTING/rK.json; None: none.
    stats_file: str | None = None
    forkable: Forkable | None = None  # how to fork it, when it is written in Python


@dataclass(frozen=True)
class Protocol:
    """One routing protocol: its name, the port of its control traffic, its daemon."""

    name: str
    # The UDP port its control packets are counted on in the captures (required: with none,
    # its overhead would be counted on another protocol's port).
    control_port: int
    daemon: Daemon | None  # None: no daemon (no routing, or the oracle's controller routes)
    proactive: bool = False  # a proactive protocol, which the protocols study sets against AODV
    about: str = ""  # one line: what it is

    def __post_init__(self) -> None:
        port = self.control_port
        if isinstance(port, bool) or not isinstance(port, int) or not 0 < port < 65536:
            raise ValueError(f"routing protocol {self.name!r}: control port {port!r} is not a "
                             "UDP port (1 to 65535)")  # fmt: skip
        if self.daemon is not None and not self.daemon.argv:
            raise ValueError(f"routing protocol {self.name!r}: its daemon names no argv builder")


def _registry(*protocols: Protocol) -> dict[str, Protocol]:
    """The registry by name; a name given twice is refused."""
    out: dict[str, Protocol] = {}
    for p in protocols:
        if p.name in out:
            raise ValueError(f"routing protocol {p.name!r} registered twice")
        out[p.name] = p
    return out


REGISTRY: dict[str, Protocol] = _registry(
    Protocol(
        "aodv", AODV_PORT, about="this project's AODV daemon (RFC 3561), on demand",
        daemon=Daemon(
            argv="aodv_argv",
            programs=("tb-aodv",),  # the compiled daemon; the Python one is titled "rK aodv"
            ready_file="r{k}.aodv.json",  # written first once its socket, TUN and routes are up
            stats_file="r{k}.aodv.json",
            forkable=Forkable(
                module="aodv.__main__",
                args="aodv_args",
                preload=("aodv.__main__", "aodv.daemon", "aodv.params", "aodv.sim"),
                warm=(("aodv.sim", "warm_up", ()),),
            ),
        ),
    ),
    Protocol(
        "babel", 6696, proactive=True, about="Debian's babeld (RFC 8966), proactive",
        daemon=Daemon(argv="babel_argv", tools={"babeld": "babeld"}, programs=("babeld",)),
    ),
    Protocol(
        "batman", 4305, proactive=True, about="Debian's batmand (B.A.T.M.A.N. III), proactive",
        daemon=Daemon(
            argv="batman_argv",
            tools={"batmand": "batmand", "unshare": "util-linux"},
            programs=("batmand",),
        ),
    ),
    Protocol(
        "oracle", AODV_PORT, daemon=None,  # sends nothing: its captures are watched on AODV's
        about="shortest-path routes from the topology controller (topology.oracle)",
    ),
    Protocol("none", AODV_PORT, daemon=None, about="no routing: routes are the user's"),
)  # fmt: skip

ROUTINGS = tuple(REGISTRY)  # the choices of --routing; the first is the default
