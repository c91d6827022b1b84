"""Impairments on one direction of one link: netem where the kernel has it, nftables where not.

A link end `lixj` in the medium namespace carries frames from robot i to robot j, so its
egress qdisc shapes exactly that direction.

Describe, then apply the difference (docs/architecture.md, "describe first, build second"):
`wanted_qdiscs` and `nft_commands` are pure functions from an impairment to the qdisc tree
and the nftables commands a link end should have; `plan` compares what an end has with what
it should have and returns only the requests that close the gap, as CORE's tc_cmd does. An
unchanged end costs nothing, a changed rate or loss on a tree of the same shape is changed in
place (`tc qdisc replace`), and only a change of shape (a rate added or dropped) rebuilds the
tree. `Impairer` is the thin loop that sends a plan's requests and records what each end has.

- With sch_netem: a netem root qdisc (loss, delay, jitter), and a tbf child for a rate limit.
- Without sch_netem (this project's development kernel): loss becomes an nftables rule in the
  medium namespace's own bridge-family table, `numgen random mod 10000 < N drop` in a chain per
  link end, reached through a verdict map keyed by output interface; rate becomes a root tbf;
  delay and jitter are refused with an error that names the missing module.

Delays scale with the run's time scale like every other timer (Impairment.scaled), and rates
with it (a link K times faster in emulated time carries K times the bits per wall second); so
does the longest a frame may queue in a rate limit (tbf's latency, TBF_LATENCY_US of emulated
time), so that the queue holds as many emulated milliseconds at every scale.
"""

import errno
import functools
import logging
import math
import shutil
import subprocess
from dataclasses import dataclass

from pyroute2.netlink.exceptions import NetlinkError

from common.errors import TestbedError
from topology.kernel import netns
from topology.spec import Impairment

log = logging.getLogger(__name__)

NFT_TABLE = "testbed"
NFT_MAP = "lossy"
TBF_BURST = 32 * 1024
TBF_LATENCY_US = 50_000


class MissingKernelFeature(RuntimeError):
    """The kernel lacks something an impairment needs; the message names the module."""


def missing_feature(imp: Impairment, netem: bool, nft: bool) -> str | None:
    """What this machine lacks to apply `imp` (one line for the user), or None: the one rule
    of which impairment needs what. Delay and jitter need sch_netem; loss needs sch_netem or
    else nftables (a rule in the medium namespace's bridge table); a rate limit needs only
    tbf, which every kernel has."""
    if (imp.delay_ms > 0 or imp.jitter_ms > 0) and not netem:
        return (
            "delay and jitter (--delay, --jitter) need the sch_netem kernel module, which this "
            "kernel lacks (loss works without it; `make vm-test` runs netem under a stock kernel)"
        )
    if imp.loss_pct > 0 and not netem and not nft:
        return "loss (--loss) without sch_netem needs nftables: `nft` is not installed"
    return None


@functools.cache
def kernel_has_netem() -> bool:
    """Whether this kernel can make a netem qdisc: the one probe of the project (a kernel
    module is the kernel's, not a namespace's). Tried once per process, on the loopback of a
    throwaway network namespace (`unshare --net`, gone when tc exits); needs root."""
    try:
        r = subprocess.run(
            [
                "unshare",
                "--net",
                "tc",
                "qdisc",
                "add",
                "dev",
                "lo",
                "root",
                "netem",
                "delay",
                "1ms",
            ],
            capture_output=True,
            timeout=10,
        )
    except (OSError, subprocess.TimeoutExpired):
        return False
    return r.returncode == 0


def nft_chain(ifname: str) -> str:
    return f"loss-{ifname}"


def nft_loss_rules(ifname: str, loss_pct: float) -> str:
    """nft commands that make `ifname` drop loss_pct% of the frames it forwards."""
    chain = nft_chain(ifname)
    threshold = round(loss_pct * 100)  # in 1/10000
    # numgen yields 0..9999, and nft refuses a comparison with a constant out of that range.
    match = "" if threshold >= 10000 else f"numgen random mod 10000 < {threshold} "
    return (
        f"add chain bridge {NFT_TABLE} {chain}\n"
        f"flush chain bridge {NFT_TABLE} {chain}\n"
        f"add rule bridge {NFT_TABLE} {chain} {match}counter drop\n"
        f'add element bridge {NFT_TABLE} {NFT_MAP} {{ "{ifname}" : jump {chain} }}\n'
    )


def nft_unloss_rules(ifname: str) -> str:
    chain = nft_chain(ifname)
    return (
        f'delete element bridge {NFT_TABLE} {NFT_MAP} {{ "{ifname}" }}\n'
        f"delete chain bridge {NFT_TABLE} {chain}\n"
    )


NFT_SETUP = (
    f"add table bridge {NFT_TABLE}\n"
    f"add map bridge {NFT_TABLE} {NFT_MAP} {{ type ifname : verdict; }}\n"
    f"add chain bridge {NFT_TABLE} forward"
    " { type filter hook forward priority 0; policy accept; }\n"
    f"flush chain bridge {NFT_TABLE} forward\n"  # idempotent when a second process attaches
    f"add rule bridge {NFT_TABLE} forward oifname vmap @{NFT_MAP}\n"
)


# -- the builders: pure ----------------------------------------------------------------------


@dataclass(frozen=True)
class Qdisc:
    """One qdisc of a link end's egress tree, as pyroute2's `tc` takes it."""

    kind: str  # "netem" or "tbf"
    handle: str
    parent: str | None  # None: the root
    params: tuple[tuple[str, int | float | str], ...]

    def kwargs(self) -> dict:
        kw = dict(self.params, handle=self.handle)
        if self.parent is not None:
            kw["parent"] = self.parent
        return kw


def tc_rate(rate_kbit: float) -> str:
    """A rate as pyroute2's tc parser takes it: a whole number of bits per second and the
    unit. (It splits the number from the unit at the first non-digit, so "100.0kbit" reads as
    100 of the unit ".0kbit".) Never 0: a tbf of rate 0 would carry nothing."""
    if not (rate_kbit > 0 and math.isfinite(rate_kbit)):
        raise ValueError(f"rate {rate_kbit} kbit/s must be a finite number > 0")
    return f"{max(1, round(rate_kbit * 1000))}bit"


def _tbf(handle: str, parent: str | None, rate_kbit: float, time_scale: float) -> Qdisc:
    latency_us = max(1, round(TBF_LATENCY_US / time_scale))
    params = (("rate", tc_rate(rate_kbit)), ("burst", TBF_BURST), ("latency", latency_us))
    return Qdisc("tbf", handle, parent, params)


def wanted_qdiscs(imp: Impairment, netem: bool, time_scale: float = 1.0) -> tuple[Qdisc, ...]:
    """The egress qdisc tree, root first, that gives a link end `imp` (already scaled to
    `time_scale`, which also divides the rate limit's queueing latency)."""
    if not netem:
        return (_tbf("1:", None, imp.rate_kbit, time_scale),) if imp.rate_kbit > 0 else ()
    if imp.is_none:
        return ()
    root = Qdisc(
        "netem",
        "1:",
        None,
        (
            ("delay", int(imp.delay_ms * 1000)),
            ("jitter", int(imp.jitter_ms * 1000)),
            ("loss", imp.loss_pct),
        ),
    )
    return (root, _tbf("10:", "1:1", imp.rate_kbit, time_scale)) if imp.rate_kbit > 0 else (root,)


def nft_commands(ifname: str, have: Impairment, want: Impairment, netem: bool) -> str:
    """nft commands that take a link end's loss rule from `have` to `want`; "" when they
    agree. With netem, loss is netem's and nftables is not used."""
    if netem:
        return ""
    old = nft_loss_rules(ifname, have.loss_pct) if have.loss_pct > 0 else ""
    new = nft_loss_rules(ifname, want.loss_pct) if want.loss_pct > 0 else ""
    if new == old:
        return ""
    return new or nft_unloss_rules(ifname)


@dataclass(frozen=True)
class TcRequest:
    command: str  # "del" (the whole root tree), "add" or "replace"
    qdisc: Qdisc | None  # None with "del"


@dataclass(frozen=True)
class Plan:
    """What to send to one link end: tc requests in order, then nft commands."""

    tc: tuple[TcRequest, ...]
    nft: str

    @property
    def empty(self) -> bool:
        return not self.tc and not self.nft


CLEAR = TcRequest("del", None)


def tc_diff(have: tuple[Qdisc, ...], want: tuple[Qdisc, ...]) -> tuple[TcRequest, ...]:
    """The tc requests that turn the tree `have` into `want`.

    Same tree: nothing. No tree wanted: delete the root. Same shape (kinds, handles,
    parents): replace the qdiscs whose parameters changed, in place, so frames never pass
    unshaped meanwhile. Otherwise delete the root (tolerated when there is none) and add the
    wanted tree root first."""
    if have == want:
        return ()
    if not want:
        return (CLEAR,)

    def shape(tree):
        return [(q.kind, q.handle, q.parent) for q in tree]

    if shape(have) == shape(want):
        return tuple(TcRequest("replace", q) for q, h in zip(want, have, strict=True) if q != h)
    return (CLEAR, *(TcRequest("add", q) for q in want))


def plan(ifname: str, have: Impairment, want: Impairment, netem: bool, time_scale: float) -> Plan:
    """The requests that take link end `ifname` from impairment `have` to `want` (both in
    emulated time: scaled here)."""
    h, w = have.scaled(time_scale), want.scaled(time_scale)
    return Plan(
        tc_diff(wanted_qdiscs(h, netem, time_scale), wanted_qdiscs(w, netem, time_scale)),
        nft_commands(ifname, h, w, netem),
    )


# -- the loop that applies them -------------------------------------------------------------


class Impairer:
    """Keeps each link end's qdiscs and nft rules in step with its wanted Impairment."""

    def __init__(self, ns: str, worker: netns.NsWorker, time_scale: float = 1.0):
        self.ns = ns
        self.worker = worker
        self.time_scale = time_scale
        self.have: dict[str, Impairment] = {}
        self._netem: bool | None = None
        self._nft_ready = False

    @property
    def netem(self) -> bool:
        if self._netem is None:
            self._netem = kernel_has_netem()
            log.info("%s: sch_netem %s", self.ns, "available" if self._netem else "missing")
        return self._netem

    def check(self, imp: Impairment) -> None:
        """Raise MissingKernelFeature if this machine cannot apply `imp` (missing_feature)."""
        missing = missing_feature(imp, self.netem, shutil.which("nft") is not None)
        if missing:
            raise MissingKernelFeature(missing)

    def apply(self, ifname: str, imp: Impairment) -> None:
        old = self.have.get(ifname, Impairment())
        if old == imp:
            return
        self.check(imp)
        p = plan(ifname, old, imp, self.netem, self.time_scale)
        if p.tc:
            want = wanted_qdiscs(imp.scaled(self.time_scale), self.netem, self.time_scale)
            self.worker.call(lambda ipr: _send(ipr, ifname, p.tc, want))
        if p.nft:
            self._nft(p.nft)
        if imp.is_none:
            self.have.pop(ifname, None)
        else:
            self.have[ifname] = imp

    def forget(self, i: int, j: int) -> None:
        """The link i-j is gone (its qdiscs died with it); drop its nft chains too."""
        from topology import names

        for ifname in (names.link_end(i, j), names.link_end(j, i)):
            old = self.have.pop(ifname, None)
            if old is not None and old.loss_pct > 0 and not self._netem:
                self._nft(nft_unloss_rules(ifname))

    def close(self) -> None:
        self.have.clear()

    def _nft(self, commands: str) -> None:
        if not self._nft_ready:
            commands = NFT_SETUP + commands
            self._nft_ready = True
        proc = subprocess.run(
            netns.popen_argv(self.ns, ["nft", "-f", "-"]),
            input=commands,
            capture_output=True,
            text=True,
        )
        if proc.returncode != 0:
            first = (proc.stderr.strip().splitlines() or ["?"])[0]
            raise TestbedError(f"nft in {self.ns} failed: {first}")


def _clear_root(ipr, idx: int) -> None:
    try:
        ipr.tc("del", index=idx, handle="0:", parent=0xFFFFFFFF)
    except NetlinkError as exc:
        if exc.code not in (errno.ENOENT, errno.EINVAL):
            raise


def _send(ipr, ifname: str, requests: tuple[TcRequest, ...], want: tuple[Qdisc, ...]) -> None:
    """Send a plan's tc requests. An in-place replace that the kernel refuses (the tree is
    not what was recorded, e.g. the link end was made anew) falls back to a rebuild."""
    idx = ipr.link_lookup(ifname=ifname)[0]
    try:
        for r in requests:
            if r.qdisc is None:
                _clear_root(ipr, idx)
            else:
                ipr.tc(r.command, r.qdisc.kind, index=idx, **r.qdisc.kwargs())
    except NetlinkError:
        if all(r.command != "replace" for r in requests):
            raise
        _clear_root(ipr, idx)
        for q in want:
            ipr.tc("add", q.kind, index=idx, **q.kwargs())
