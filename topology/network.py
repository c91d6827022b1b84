"""A testbed's network: robot namespaces on the radio medium, captures and routing daemons.

Theory of operation. `Network(spec)` turns a NetworkSpec (plain data) into kernel objects:

1. claim the name: the state file is created exclusively *before* anything else, so a
   crash at any later point leaves a record that `testbed clean` can act on;
2. create the medium namespace and one namespace per robot (names from topology.names);
3. per robot, a bridge in the medium and a veth whose far end is the robot's wlan0
   (topology.radio.veth), addressed 10.0.0.K/32 with the sysctls docs/architecture.md lists, and
   the network timers of its namespace divided by the time scale (topology.kernel.nettimers;
   `Network.timers` is the record of what was dilated, to what, and what could not be);
4. the links the range model wants for the initial positions, with their impairments;
5. tcpdump per robot if asked, then the routing daemon per robot (topology.routing); a
   daemon written in Python is forked from a fork server started at step 1, whose imports
   run while the kernel objects are made.

Teardown (`destroy`) is the same function for a clean exit, an exception during bring-up,
`testbed net down` and `testbed clean`: stop the recorded processes (SIGTERM, then SIGKILL),
then any other process still inside our namespaces, then remove the namespaces (which takes
every interface with them) and the state. It works from names and the state file alone, so
it needs nothing from the process that built the testbed.

Moving robots recomputes the wanted links and applies only the difference. A robot whose
radio is taken out of range on purpose (`set_isolated`, a run's `--isolate`) has no link in
the wanted set, whatever the positions say, until it is let back.
"""

import contextlib
import logging
import os
import shutil
import subprocess
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict

from common.errors import TestbedError, UsageError
from common.jsonfile import write_json_atomic
from topology import names, routing, state
from topology.kernel import capture, netns, processes
from topology.kernel.forkserver import Forked, ForkServer, ForkServerError, python_env
from topology.kernel.impair import MissingKernelFeature
from topology.oracle import OracleRouter
from topology.radio import ranges
from topology.radio.los import MapError, Walls
from topology.radio.ns3wifi import Ns3Medium, medium_for
from topology.radio.veth import WLAN_INDEX
from topology.spec import (
    LOS_MODELS,
    NO_IMPAIRMENT,
    VETH,
    Impairment,
    NetworkSpec,
    Position,
    check_position,
)

log = logging.getLogger(__name__)

Pair = tuple[int, int]
CAPTURE_DRAIN_S = 0.2  # lets tcpdump read what is still queued for it before it stops


class Network:
    """One testbed's network. Use as a context manager, or up()/down() explicitly."""

    def __init__(self, spec: NetworkSpec, *, persistent: bool = False):
        self.spec = spec
        self.persistent = persistent
        self.positions: list[Position] = list(spec.positions)
        self.medium = medium_for(spec)  # veth links, or ns-3's 802.11 channel
        self.current: dict[Pair, Impairment] = {}
        self.link_impairments: dict[Pair, Impairment] = {}  # set by hand, per link
        self.state: state.TestbedState | None = None
        self.children: dict[int, subprocess.Popen] = {}
        self._owner = False
        self._routing_forks: ForkServer | None = None
        self.oracle: OracleRouter | None = None  # routing "oracle": routes from here
        self.walls: Walls | None = None  # the los range models' walls, from spec.map_png
        self._range_cache: dict[Pair, Impairment] | None = None  # the last range-model links
        self._deferred: list[state.ProcessRecord] | None = None  # see _recording
        self._state_mtime: int | None = None  # of the state file we last read or wrote
        self._adj: dict[int, set[Pair]] | None = None  # robot -> its links in current
        self.isolated: frozenset[int] = frozenset()  # robots out of everyone's range
        if spec.map_png and spec.range_model in LOS_MODELS:
            try:
                self.walls = Walls.from_png(spec.map_png, spec.map_cell)
            except MapError as exc:
                raise UsageError(str(exc)) from None

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

    # -- bring-up ---------------------------------------------------------------------------

    def __enter__(self) -> "Network":
        self.up()
        return self

    def __exit__(self, *exc) -> None:
        self.down()

    def up(self) -> None:
        preflight(self.spec)
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
        forkable = routing.FORKABLE.get(self.spec.routing)
        if forkable is not None:
            self._routing_forks = ForkServer(
                list(forkable.preload), env=python_env(),
                warm=[[m, f, list(a)] for m, f, a in forkable.warm],
                label=f"{self.name} {self.spec.routing}",
            )  # fmt: skip
        self._create_namespace(names.medium_ns(self.name))
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
        with ThreadPoolExecutor(1) as pool:
            made = pool.submit(
                lambda: [self._create_namespace(names.robot_ns(self.name, k)) for k in robots]
            )
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
                self._start_captures()
            self._start_routing()
        log.info(
            "%s: %d robots, %d links up in %.0f ms",
            self.name, self.spec.robots, len(self.current), 1000 * (time.perf_counter() - t0),
        )  # fmt: skip

    @staticmethod
    def _create_namespace(ns: str) -> None:
        try:
            netns.create(ns)
        except FileExistsError:
            raise UsageError(f"namespace {ns} already exists (try `testbed clean`)") from None

    def _start_captures(self) -> None:
        cdir = self.spec.capture_dir
        assert cdir is not None  # called only with one
        os.makedirs(cdir, exist_ok=True)
        # What the captures are of (the routing protocol, for `testbed metrics`), next to the
        # daemons' logs that teardown keeps (_keep_logs).
        os.makedirs(os.path.join(cdir, "daemons"), exist_ok=True)
        about = state.spec_to_dict(self.spec)
        if self.timers is not None:
            about["network_timers"] = self.timers.to_dict()
        write_json_atomic(os.path.join(cdir, "daemons", "network.json"), about)
        started = []
        for k in self.spec.robot_ids():
            logp = os.path.join(self.state_dir, f"r{k}.tcpdump.log")
            with open(logp, "w") as logf:
                proc = self.spawn(k, capture.tcpdump_argv(cdir, k), role="tcpdump",
                                  stdout=subprocess.DEVNULL, stderr=logf)  # fmt: skip
            started.append((logp, proc))
        for logp, proc in started:
            try:
                capture.wait_ready(logp, proc)
            except RuntimeError as exc:
                raise TestbedError(f"packet capture: {exc}") from None

    def _start_routing(self) -> None:
        started = []
        forkable = routing.FORKABLE.get(self.spec.routing)
        for k in self.spec.robot_ids():
            argv = routing.argv_for(self.spec, k, self.state_dir)
            if argv is None:
                continue
            logp = routing.log_file(self.spec.routing, k, self.state_dir)
            proc: Forked | subprocess.Popen
            if forkable is not None and self._routing_forks is not None:  # started iff forkable
                open(logp, "w").close()  # the child appends
                args = forkable.args(k, self.state_dir, self.spec)
                try:
                    proc = self._routing_forks.spawn(
                        self.robot_ns(k), forkable.module, args, logp,
                        title=f"r{k} {self.spec.routing}",
                    )  # fmt: skip
                except ForkServerError as exc:
                    raise TestbedError(f"{self.spec.routing} daemon of r{k}: {exc}") from None
                self.adopt(k, proc, self.spec.routing)
            else:
                with open(logp, "w") as logf:
                    proc = self.spawn(k, argv, role=self.spec.routing, stdout=logf,
                                      stderr=subprocess.STDOUT)  # fmt: skip
            started.append((k, proc, logp))
        # Return only once every daemon can route, so the first packet is not lost to a race.
        deadline = time.monotonic() + routing.READY_TIMEOUT_S
        for k, proc, logp in started:
            ready = routing.ready_file(self.spec.routing, k, self.state_dir)
            while ready and not os.path.exists(ready):
                if proc.poll() is not None or time.monotonic() > deadline:
                    with open(logp) as f:
                        last = (f.read().strip().splitlines() or ["(no output)"])[-1]
                    what = "exited" if proc.poll() is not None else "did not start in time"
                    raise TestbedError(f"{self.spec.routing} daemon of r{k} {what}: {last}")
                time.sleep(0.01)

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

    def _range_links(self, moved: set[int] | None = None) -> dict[Pair, Impairment]:
        """The range model's links for the current positions. With the distance models and
        `moved` given, only the links of the robots that moved are computed again (the rest
        come from the last call): what keeps a feed of many moves cheap at 1000 robots."""
        cached = self._range_cache
        if moved is not None and cached is not None and self.spec.range_model in ("disc", "lossy"):
            links = {p: v for p, v in cached.items() if p[0] not in moved and p[1] not in moved}
            links.update(ranges.links_of(self.positions, moved, self.spec.comm_range,
                                         self.spec.range_model))  # fmt: skip
        else:
            links = ranges.wanted_links(
                self.positions, self.spec.comm_range, self.spec.range_model,
                self.walls, self.spec.wall_loss_pct,
            )  # fmt: skip
        self._range_cache = links
        return links

    def wanted(self, moved: set[int] | None = None) -> dict[Pair, Impairment]:
        """The links (with their impairments) the positions call for; `moved`: the robots
        that moved since the last call, if known."""
        links = self._range_links(moved)
        if self.isolated:
            links = {p: v for p, v in links.items() if not self.isolated.intersection(p)}
        base = self.spec.impairment
        if base.is_none and not self.link_impairments:
            return links  # the common case, once per world step: nothing to combine
        return {
            p: base.combined(imp).combined(self.link_impairments.get(p, NO_IMPAIRMENT))
            for p, imp in links.items()
        }

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
        if moved is not None and self.spec.range_model in ("disc", "lossy") and not self.isolated:
            add, remove, change, wanted = self._diff_moved(moved)
        else:
            wanted = self.wanted()
            add, remove, change = ranges.diff(self.current, wanted)
            self._adj = None
        # Impairments before enabling, so no frame crosses a link without its loss and delay.
        self.medium.create_pairs(add)
        for p in add + change:
            self.medium.set_link_impairment(*p, wanted[p])
        self.medium.set_links(add, remove)
        if moved is None or self.spec.range_model not in ("disc", "lossy") or self.isolated:
            self.current = wanted
        if self.oracle is not None and (add or remove):
            self.oracle.update(self.current)  # routes in place before the move returns
        return add, remove

    def _diff_moved(
        self, moved: set[int]
    ) -> tuple[list[Pair], list[Pair], list[Pair], dict[Pair, Impairment]]:
        """What a move of `moved` changes, in O(links of the moved robots), with self.current
        updated in place: only links of a robot that moved can change under the distance
        models. A feed of single moves at 1000 robots would otherwise pay for every link
        (diffing 2000 links: ~4 ms) per update. Returns (add, remove, change, new links)."""
        if self._adj is None:
            self._adj = {}
            for p in self.current:
                self._adj.setdefault(p[0], set()).add(p)
                self._adj.setdefault(p[1], set()).add(p)
        self._range_cache = None  # wanted() recomputes in full from now on
        new = ranges.links_of(self.positions, moved, self.spec.comm_range, self.spec.range_model)
        base = self.spec.impairment
        if not base.is_none or self.link_impairments:
            new = {
                p: base.combined(imp).combined(self.link_impairments.get(p, NO_IMPAIRMENT))
                for p, imp in new.items()
            }
        old = set().union(*(self._adj.get(k, ()) for k in moved))
        add = sorted(set(new) - old)
        remove = sorted(old - set(new))
        change = sorted(p for p in old & set(new) if new[p] != self.current[p])
        for p in remove:
            del self.current[p]
            self._adj[p[0]].discard(p)
            self._adj[p[1]].discard(p)
        for p in add:
            self._adj.setdefault(p[0], set()).add(p)
            self._adj.setdefault(p[1], set()).add(p)
        for p in add + change:
            self.current[p] = new[p]
        return add, remove, change, new

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
        return self._moved()

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
        self.link_impairments = {
            _pair(key): Impairment(**fields) for key, fields in st.link_impairments.items()
        }
        self._range_cache = None
        self.current = self.wanted()
        self._adj = None

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


# The Debian/Ubuntu package of each tool preflight asks for.
TOOL_PACKAGES = {"ip": "iproute2", "unshare": "util-linux"}


def preflight(spec: NetworkSpec) -> None:
    """What can be checked before touching the kernel: privileges and tools."""
    if os.geteuid() != 0:
        raise UsageError("network namespaces need root: run this under sudo")
    missing = [t for t in ("ip",) if shutil.which(t) is None]
    if spec.capture_dir and shutil.which("tcpdump") is None:
        missing.append("tcpdump")
    missing += routing.missing_tools(spec.routing)
    if missing:
        pkgs = ", ".join(dict.fromkeys(TOOL_PACKAGES.get(t, t) for t in missing))
        raise UsageError(
            f"missing tool(s): {', '.join(missing)} (package(s) {pkgs}: `sudo make setup` "
            "installs those the distribution has)"
        )


def our_namespaces(name: str) -> list[str]:
    return [ns for ns in netns.list_names() if (names.parse_ns(ns) or ("",))[0] == name]


def destroy(name: str, children: dict[int, subprocess.Popen] | None = None) -> None:
    """Remove everything testbed `name` made: processes, namespaces, run dir, state. A state
    file another user could have written is ignored (one warning): none of the processes it
    names is signalled, only those the kernel shows inside the testbed's namespaces."""
    try:
        st = state.read(name)
    except state.UntrustedState as exc:
        log.warning("%s; signalling only the processes inside tb-%s-* namespaces", exc, name)
        st = None
    namespaces = our_namespaces(name)
    if st is not None:
        # Captures last: what the daemons send as they stop belongs in the pcaps.
        last = [p for p in st.processes if p.role == "tcpdump"]
        processes.stop([p for p in st.processes if p.role != "tcpdump"], children)
        if last:
            time.sleep(CAPTURE_DRAIN_S)
            processes.stop(last, children)
    stray = [pid for pid in processes.pids_in_namespaces(namespaces) if pid != os.getpid()]
    if stray:
        processes.stop(
            [state.ProcessRecord(pid, state.proc_start_time(pid), 0, "stray") for pid in stray],
            children,
        )
    for ns in namespaces:
        netns.remove(ns)
    _keep_logs(name, st)
    shutil.rmtree(state.run_dir(name), ignore_errors=True)
    state.remove(name)


def _mtime(name: str) -> int | None:
    try:
        return os.stat(state.state_path(name)).st_mtime_ns
    except FileNotFoundError:
        return None


def _pair(key: str) -> Pair:
    """A link of the state file's `link_impairments` ("i-j") as a pair."""
    i, j = key.split("-")
    return int(i), int(j)


def _keep_logs(name: str, st: state.TestbedState | None) -> None:
    """Nothing is lost: when the testbed captured packets, the daemons' logs and statistics
    (written to its run dir as they stop) go next to the pcaps, in CAPTURE_DIR/daemons/."""
    capture_dir = st.spec.get("capture_dir") if st else None
    src = state.run_dir(name)
    if not capture_dir or not os.path.isdir(src):
        return
    dst = os.path.join(capture_dir, "daemons")
    os.makedirs(dst, exist_ok=True)
    for entry in os.listdir(src):
        if entry.endswith((".log", ".json")):
            shutil.copy2(os.path.join(src, entry), os.path.join(dst, entry))
