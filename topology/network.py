"""A testbed's network: robot namespaces on the radio medium, captures and routing daemons.

Theory of operation. `Network(spec)` turns a NetworkSpec (plain data) into kernel objects
(`up`):

1. claim the name: the state file is created exclusively *before* anything else, so a
   crash at any later point leaves a record that `testbed clean` can act on;
2. create the medium namespace and one namespace per robot (names from topology.names);
3. per robot, a bridge in the medium and a veth whose far end is the robot's wlan0
   (topology.radio.veth), addressed 10.0.0.K/32 with the sysctls docs/architecture.md lists, and
   the network timers of its namespace divided by the time scale (topology.kernel.nettimers;
   `Network.timers` is the record of what was dilated, to what, and what could not be);
4. the links the range model wants for the initial positions, with their impairments;
5. tcpdump per robot if asked, then the routing daemon per robot (topology.bringup,
   topology.routing); a daemon written in Python is forked from a fork server started at
   step 1, whose imports run while the kernel objects are made.

Teardown (`down`; topology.teardown.destroy) is the same function for a clean exit, an
exception during bring-up, `testbed net down` and `testbed clean`, and works from names and
the state file alone.

While up, moving robots recomputes the wanted links and applies only the difference
(topology.linkchanges says what changes; this module applies it to the medium and the
oracle's routes, and keeps the state file's positions and impairments). A robot whose radio
is taken out of range on purpose (`set_isolated`, a run's `--isolate`) has no link in the
wanted set, whatever the positions say, until it is let back.
"""

import contextlib
import logging
import os
import subprocess
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict

from common.errors import UsageError
from topology import bringup, names, state
from topology.bringup import preflight as preflight
from topology.kernel import netns, processes
from topology.kernel.forkserver import ForkServer
from topology.kernel.impair import MissingKernelFeature
from topology.linkchanges import Links, Pair
from topology.oracle import OracleRouter
from topology.radio.los import Walls
from topology.radio.ns3wifi import Ns3Medium, medium_for
from topology.radio.slack import Slack
from topology.radio.veth import WLAN_INDEX
from topology.spec import (
    VETH,
    Impairment,
    NetworkSpec,
    Position,
    check_position,
)
from topology.teardown import destroy

log = logging.getLogger(__name__)


class Network:
    """One testbed's network. Use as a context manager, or up()/down() explicitly."""

    def __init__(self, spec: NetworkSpec, *, persistent: bool = False):
        self.spec = spec
        self.persistent = persistent
        self.positions: list[Position] = list(spec.positions)
        self.medium = medium_for(spec)  # veth links, or ns-3's 802.11 channel
        self.state: state.TestbedState | None = None
        self.children: dict[int, subprocess.Popen] = {}
        self._owner = False
        self._routing_forks: ForkServer | None = None
        self.oracle: OracleRouter | None = None  # routing "oracle": routes from here
        self._deferred: list[state.ProcessRecord] | None = None  # see _recording
        self._state_mtime: int | None = None  # of the state file we last read or wrote
        self.linkset = Links(spec, Links.walls_of(spec))  # the links up now, what changes them
        self._slack = Slack(spec)  # how far set_positions' moves may go with the links as they are

    # -- names ------------------------------------------------------------------------------

    @property
    def name(self) -> str:
        return self.spec.name

    def robot_ns(self, k: int) -> str:
        self._check_robot(k)
        return names.robot_ns(self.name, k)

    @property
    def timers(self):
        """The robot namespaces' network timers (topology.kernel.nettimers.NetworkTimers), None
        before they are made and for a testbed taken up by `attach`."""
        return self.medium.timers

    @property
    def state_dir(self) -> str:
        return state.run_dir(self.name)

    def _check_robot(self, k: int) -> None:
        if not 1 <= k <= self.spec.robots:
            raise UsageError(f"testbed {self.name} has robots r1..r{self.spec.robots}, not r{k}")

    # -- the link set (topology.linkchanges) --------------------------------------------------

    @property
    def current(self) -> dict[Pair, Impairment]:
        """The links up now, with their impairments."""
        return self.linkset.current

    @current.setter
    def current(self, links: dict[Pair, Impairment]) -> None:
        self.linkset.current = links

    @property
    def link_impairments(self) -> dict[Pair, Impairment]:
        """The impairments set by hand, per link."""
        return self.linkset.by_hand

    @link_impairments.setter
    def link_impairments(self, by_hand: dict[Pair, Impairment]) -> None:
        self.linkset.by_hand = by_hand

    @property
    def isolated(self) -> frozenset[int]:
        """The robots out of everyone's radio range (set_isolated)."""
        return self.linkset.isolated

    @isolated.setter
    def isolated(self, robots: frozenset[int]) -> None:
        self.linkset.isolated = robots

    @property
    def walls(self) -> Walls | None:
        return self.linkset.walls

    # -- bring-up ---------------------------------------------------------------------------

    def __enter__(self) -> "Network":
        self.up()
        return self

    def __exit__(self, *exc) -> None:
        self.down()

    def up(self) -> None:
        bringup.preflight(self.spec)
        self.state = state.TestbedState.new(self.spec)
        try:
            state.create(self.name, self.state)
        except FileExistsError:
            raise UsageError(f"testbed name {self.name!r} is already in use") from None
        self._owner = True
        try:
            self._build()
        except BaseException:
            self.down()
            raise
        if self.persistent:
            self.state.persistent = True
            self._save()

    def _build(self) -> None:
        t0 = time.perf_counter()
        state.make_run_dir(self.name)
        robots = list(self.spec.robot_ids())
        self._routing_forks = bringup.routing_fork_server(self.spec)
        bringup.create_namespace(names.medium_ns(self.name))
        self.medium.open()
        self.medium.setup()
        if not self.spec.impairment.is_none:
            assert self.medium.impairer is not None  # open() made it
            try:
                self.medium.impairer.check(self.spec.impairment)
            except MissingKernelFeature as exc:
                raise UsageError(str(exc)) from None

        # The kernel brings new veths' carriers up in the background (linkwatch): links first,
        # then the robots' interfaces meanwhile; _apply_positions waits for the links before
        # switching them on. The robots' namespaces are made in a thread meanwhile: both are
        # kernel work (the thread runs while the other waits in a netlink send), and on two
        # cores this saves ~a third of the namespaces' cost (~1 ms a robot).
        def robot_namespaces() -> None:
            for k in robots:
                bringup.create_namespace(names.robot_ns(self.name, k))

        with ThreadPoolExecutor(1) as pool:
            made = pool.submit(robot_namespaces)
            self.medium.add_bridges(robots)
            self.medium.create_pairs(sorted(self.wanted()))
            made.result()
        self.medium.add_robot_ports(robots)
        self.medium.configure_robots(robots)
        if isinstance(self.medium, Ns3Medium):  # spec.medium == "ns3-wifi"
            self.adopt_host_process(self.medium.start(self.positions), "ns3-wifi")
        self._apply_positions()
        if self.spec.routing == "oracle":
            self.oracle = OracleRouter(self.name, robots, WLAN_INDEX)
            self.oracle.update(self.current)
        with self._recording():
            if self.spec.capture_dir:
                bringup.start_captures(self)
            bringup.start_routing(self, self._routing_forks)
        log.info(
            "%s: %d robots, %d links up in %.0f ms",
            self.name, self.spec.robots, len(self.current), 1000 * (time.perf_counter() - t0),
        )  # fmt: skip

    # -- processes --------------------------------------------------------------------------

    def spawn(self, k: int, argv: list[str], *, role: str, **popen_kwargs) -> subprocess.Popen:
        """Start argv inside robot k's namespace; it is stopped at teardown."""
        self._check_robot(k)
        proc = processes.spawn(self.robot_ns(k), argv, **popen_kwargs)
        self.children[proc.pid] = proc
        self._record([processes.record(proc, k, role)])
        return proc

    def _record(self, records: list[state.ProcessRecord]) -> None:
        """Add processes to the state file; inside _recording() they wait for its end, so a
        bring-up of 1000 daemons writes the file once, not 1000 times (the file grows with
        the team: writing it per process was quadratic, 9 s of a 200-robot bring-up)."""
        if self._deferred is not None:
            self._deferred.extend(records)
            return
        with state.locked(self.name):
            self.state = state.read(self.name) or self.state
            assert self.state is not None  # up() or attach() made it
            self.state.processes.extend(records)
            state.write(self.name, self.state)

    @contextlib.contextmanager
    def _recording(self):
        """Record the processes started in this block in one write, at its end; also when
        the block fails, so that teardown finds every one of them."""
        self._deferred = []
        try:
            yield
        finally:
            records, self._deferred = self._deferred, None
            if records:
                self._record(records)

    def adopt(self, k: int, proc, role: str) -> None:
        """Record a process that was started in robot k's namespace by other means (the fork
        server): teardown stops it like the ones `spawn` started. `proc` answers poll()."""
        self._check_robot(k)
        self.children[proc.pid] = proc
        self._record([processes.record(proc, k, role)])

    def adopt_host_process(self, proc, role: str) -> None:
        """Record a helper that runs in the host namespace for this testbed (the view of a
        `net up`): teardown stops it by its pid like the robots' processes (robot 0)."""
        self.children[proc.pid] = proc
        self._record([processes.record(proc, 0, role)])

    def process(self, k: int, role: str):
        """The newest live process of `role` (e.g. "aodv", the routing daemon) that this
        Network started in robot k, by spawn or adopt; None if there is none."""
        for rec in reversed(self.state.processes if self.state else []):
            proc = self.children.get(rec.pid)
            if rec.robot == k and rec.role == role and proc is not None and proc.poll() is None:
                return proc
        return None

    def stop(self, role: str) -> None:
        """Stop every process of this role (SIGTERM, then SIGKILL), e.g. the routing daemons
        so that they write their final statistics before the results are collected."""
        records = [p for p in (self.state.processes if self.state else []) if p.role == role]
        processes.stop(records, self.children)

    def exec(self, k: int, argv: list[str], **run_kwargs) -> subprocess.CompletedProcess:
        """Run argv inside robot k's namespace to completion."""
        self._check_robot(k)
        return subprocess.run(netns.popen_argv(self.robot_ns(k), argv), **run_kwargs)

    # -- positions and links ----------------------------------------------------------------

    def wanted(self, moved: set[int] | None = None) -> dict[Pair, Impairment]:
        """The links (with their impairments) the positions call for; `moved`: the robots
        that moved since the last call, if known."""
        return self.linkset.wanted(self.positions, moved)

    def impair(self, i: int, j: int, imp: Impairment) -> None:
        """Impair link i-j (both directions) on top of the testbed-wide impairment and the
        range model's, now and whenever the two robots are linked; Impairment() clears it."""
        for k in (i, j):
            self._check_robot(k)
        if i == j:
            raise UsageError("a link joins two different robots")
        pair = (min(i, j), max(i, j))
        assert self.medium.impairer is not None  # the medium is open while we are up
        try:
            self.medium.impairer.check(imp)
        except MissingKernelFeature as exc:
            raise UsageError(str(exc)) from None
        if imp.is_none:
            self.link_impairments.pop(pair, None)
        else:
            self.link_impairments[pair] = imp
        self._moved()

    def set_isolated(self, robots) -> tuple[list[Pair], list[Pair]]:
        """Take `robots` out of everyone's radio range (every link of theirs off, whatever the
        positions say) and let every other robot back; links follow before this returns.
        Returns (added, removed). Only on the veth medium (on ns3-wifi the channel decides
        who hears whom)."""
        robots = frozenset(robots)
        for k in robots:
            self._check_robot(k)
        if self.spec.medium != VETH:
            raise UsageError("a robot can be isolated only on the veth medium")
        self.isolated = robots
        return self._moved()

    def _apply_positions(self, moved: set[int] | None = None) -> tuple[list[Pair], list[Pair]]:
        if isinstance(self.medium, Ns3Medium):  # spec.medium == "ns3-wifi"
            self.medium.set_positions(self.positions)  # the channel decides who hears whom
        incremental = self.linkset.incremental(moved)
        add, remove, change, wanted = self.linkset.changes(self.positions, moved)
        # Impairments before enabling, so no frame crosses a link without its loss and delay.
        self.medium.create_pairs(add)
        for p in add + change:
            self.medium.set_link_impairment(*p, wanted[p])
        self.medium.set_links(add, remove)
        if not incremental:
            self.current = wanted
        if self.oracle is not None and (add or remove):
            self.oracle.update(self.current)  # routes in place before the move returns
        return add, remove

    def move(self, k: int, xy: Position) -> tuple[list[Pair], list[Pair]]:
        """Move robot k; links follow before this returns. Returns (added, removed)."""
        return self.move_many({k: xy})

    def move_many(
        self, moves: dict[int, Position], *, save: bool = True
    ) -> tuple[list[Pair], list[Pair]]:
        """Move several robots at once ({robot: (x, y)}); links follow, in one batch, before
        this returns. Returns (added, removed). save=False leaves the state file's positions
        as they were (a feed saves now and then, not on every batch)."""
        if self.persistent:
            self.refresh()
        for k, xy in moves.items():
            self._check_robot(k)
            try:
                self.positions[k - 1] = check_position(xy, f"position of r{k}")
            except ValueError as exc:
                raise UsageError(str(exc)) from None
        return self._moved(set(moves), save=save)

    def set_positions(self, positions: list[Position]) -> tuple[list[Pair], list[Pair]]:
        """Move every robot at once (one world step). Returns (added, removed) links."""
        if len(positions) != self.spec.robots:
            raise ValueError(f"{len(positions)} positions for {self.spec.robots} robots")
        try:
            self.positions = [
                check_position(p, f"position of r{k}") for k, p in enumerate(positions, 1)
            ]
        except ValueError as exc:
            raise UsageError(str(exc)) from None
        if self._slack.holds(self.positions, bool(self.linkset.isolated) or self.persistent):
            return [], []  # no link can have changed: the range model is not asked
        return self._slack.measured(self.positions, self._moved())

    def _moved(
        self, moved: set[int] | None = None, save: bool = True
    ) -> tuple[list[Pair], list[Pair]]:
        diff = self._apply_positions(moved)
        if self.persistent and save:
            self._save()
        return diff

    def refresh(self) -> None:
        """Take up what another process (a trace player, a feed, `net move`) saved since we
        last read or wrote the state file: its positions, and the links they make (which
        that process applied before saving). A stat when nothing changed."""
        mtime = _mtime(self.name)
        if mtime is None or mtime == self._state_mtime:
            return
        st = state.read(self.name)
        if st is None:
            return
        self._state_mtime = mtime
        self.positions = [(x, y) for x, y in st.positions]
        by_hand = {_pair(key): Impairment(**fields) for key, fields in st.link_impairments.items()}
        self.linkset.retake(self.positions, by_hand)

    def links(self) -> set[Pair]:
        """The links up now: pairs (i, j), i < j."""
        return set(self.current)

    def save(self) -> None:
        """Write the positions and impairments to the state file (after move_many(save=False))."""
        if self.persistent:
            self._save()

    def _save(self) -> None:
        with state.locked(self.name):
            st = state.read(self.name) or self.state
            assert st is not None and self.state is not None  # up() or attach() made it
            assert self.medium.impairer is not None  # the medium is open while we are up
            st.positions = [list(p) for p in self.positions]
            st.link_impairments = {
                f"{i}-{j}": asdict(imp) for (i, j), imp in self.link_impairments.items()
            }
            st.applied = {ifname: asdict(imp) for ifname, imp in self.medium.impairer.have.items()}
            st.persistent = self.state.persistent
            self.state = st
            state.write(self.name, st)
            self._state_mtime = _mtime(self.name)

    # -- attach, detach, teardown -----------------------------------------------------------

    @classmethod
    def attach(cls, name: str) -> "Network":
        """Take up an existing testbed (made by `testbed net up`) from its state file."""
        st = state.read(name)
        if st is None or not netns.exists(names.medium_ns(name)):
            raise UsageError(f"no testbed named {name!r} is up")
        net = cls(state.spec_from_dict(st.spec), persistent=st.persistent)
        net.state = st
        net._state_mtime = _mtime(name)
        net.positions = [(x, y) for x, y in st.positions]
        net.link_impairments = {
            _pair(key): Impairment(**fields) for key, fields in st.link_impairments.items()
        }
        net.medium.open()
        assert net.medium.impairer is not None  # open() made it
        net.medium.impairer.have = {k: Impairment(**v) for k, v in st.applied.items()}
        kernel = net.medium.kernel_links()
        wanted = net.wanted()
        net.current = {p: wanted.get(p, Impairment()) for p in kernel}
        if net.spec.routing == "oracle":
            net.oracle = OracleRouter(name, net.spec.robot_ids(), WLAN_INDEX, net.current)
        return net

    def _close_oracle(self) -> None:
        if self.oracle is not None:
            self.oracle.close()
            self.oracle = None

    def detach(self) -> None:
        """Let go of the testbed without tearing it down (its daemons run on)."""
        self._close_oracle()
        self.medium.close()
        if self._routing_forks is not None:
            self._routing_forks.close()
            self._routing_forks = None
        self._owner = False

    def down(self) -> None:
        self._close_oracle()
        self.medium.close()
        try:
            destroy(self.name, self.children)
        finally:
            if self._routing_forks is not None:
                self._routing_forks.close()
                self._routing_forks = None
        self._owner = False


def _mtime(name: str) -> int | None:
    try:
        return os.stat(state.state_path(name)).st_mtime_ns
    except FileNotFoundError:
        return None


def _pair(key: str) -> Pair:
    """A link of the state file's `link_impairments` ("i-j") as a pair."""
    i, j = key.split("-")
    return int(i), int(j)
