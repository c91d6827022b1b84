"""Impairments on one direction of one link: netem where the kernel has it, nftables where not.

A link end `lixj` in the medium namespace carries frames from robot i to robot j, so its
egress qdisc shapes exactly that direction. The builder is pure (`plan`), and an end is only
touched when its wanted impairment differs from what it has (STYLE.md example 6).

- With sch_netem: a netem root qdisc (loss, delay, jitter), and a tbf child for a rate limit.
- Without sch_netem (this project's development kernel): loss becomes an nftables rule in the
  medium namespace's own bridge-family table, `numgen random mod 10000 < N drop` in a chain per
  link end, reached through a verdict map keyed by output interface; rate becomes a root tbf;
  delay and jitter are refused with an error that names the missing module.

Delays scale with the run's time scale like every other timer (Impairment.scaled).
"""

import errno
import functools
import logging
import subprocess

from pyroute2.netlink.exceptions import NetlinkError

from topology import netns
from topology.errors import TestbedError
from topology.spec import Impairment

log = logging.getLogger(__name__)

NFT_TABLE = "testbed"
NFT_MAP = "lossy"
TBF_BURST = 32 * 1024
TBF_LATENCY_US = 50_000


class MissingKernelFeature(RuntimeError):
    """The kernel lacks something an impairment needs; the message names the module."""


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
        """Raise MissingKernelFeature if this kernel cannot apply `imp`."""
        if (imp.delay_ms > 0 or imp.jitter_ms > 0) and not self.netem:
            raise MissingKernelFeature(
                "delay and jitter need the sch_netem kernel module, which this kernel lacks "
                "(loss works without it; run `make vm-test` for netem under a stock kernel)"
            )

    def apply(self, ifname: str, imp: Impairment) -> None:
        old = self.have.get(ifname, Impairment())
        if old == imp:
            return
        self.check(imp)
        real = imp.scaled(self.time_scale)
        if self.netem:
            self.worker.call(lambda ipr: self._tc_netem(ipr, ifname, real))
        else:
            self.worker.call(lambda ipr: self._tc_rate_only(ipr, ifname, real))
            if real.loss_pct > 0:
                self._nft(nft_loss_rules(ifname, real.loss_pct))
            elif old.loss_pct > 0:
                self._nft(nft_unloss_rules(ifname))
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

    # -- builders ---------------------------------------------------------------------------

    @staticmethod
    def _clear_root(ipr, idx: int) -> None:
        try:
            ipr.tc("del", index=idx, handle="0:", parent=0xFFFFFFFF)
        except NetlinkError as exc:
            if exc.code not in (errno.ENOENT, errno.EINVAL):
                raise

    def _tc_netem(self, ipr, ifname: str, imp: Impairment) -> None:
        idx = ipr.link_lookup(ifname=ifname)[0]
        self._clear_root(ipr, idx)
        if imp.is_none:
            return
        ipr.tc(
            "add",
            "netem",
            index=idx,
            handle="1:",
            delay=int(imp.delay_ms * 1000),
            jitter=int(imp.jitter_ms * 1000),
            loss=imp.loss_pct,
        )
        if imp.rate_kbit > 0:
            ipr.tc(
                "add",
                "tbf",
                index=idx,
                parent="1:1",
                handle="10:",
                rate=f"{imp.rate_kbit}kbit",
                burst=TBF_BURST,
                latency=TBF_LATENCY_US,
            )

    def _tc_rate_only(self, ipr, ifname: str, imp: Impairment) -> None:
        idx = ipr.link_lookup(ifname=ifname)[0]
        self._clear_root(ipr, idx)
        if imp.rate_kbit > 0:
            ipr.tc(
                "add",
                "tbf",
                index=idx,
                handle="1:",
                rate=f"{imp.rate_kbit}kbit",
                burst=TBF_BURST,
                latency=TBF_LATENCY_US,
            )

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
