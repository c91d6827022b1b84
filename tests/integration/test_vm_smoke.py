"""Smoke test of the netem path: proves `make vm-test` boots a kernel in which netem works.

Two namespaces of this test's own joined by a veth pair; ping RTT is measured before and
after a netem delay qdisc (added with pyroute2, as the testbed does) on both veth ends.
50 ms each way must raise the median RTT by 100 ms +-10 %. Differences of medians, never
absolute times, because the VM runs code several times slower than the host.

Skips itself where the running kernel has no sch_netem (this machine's host kernel).
"""

import os
import platform
import re
import statistics
import subprocess
import uuid
from pathlib import Path

import pytest
from pyroute2 import IPRoute

pytestmark = pytest.mark.netem

DELAY_MS = 50
PINGS = 20


def _netem_available() -> bool:
    """True if sch_netem is loaded, built in, or loadable (the kernel autoloads it)."""
    if Path("/sys/module/sch_netem").exists():
        return True
    moddir = Path("/lib/modules") / platform.release()
    for index in ("modules.dep", "modules.builtin"):
        try:
            if "/sch_netem.ko" in (moddir / index).read_text():
                return True
        except OSError:
            continue
    return False


if os.geteuid() != 0:
    pytest.skip("needs root (network namespaces)", allow_module_level=True)
if not _netem_available():
    pytest.skip(
        f"sch_netem is not available in kernel {platform.release()}; "
        "run these tests with 'make vm-test'",
        allow_module_level=True,
    )


def _run(*argv: str) -> str:
    done = subprocess.run(argv, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(argv)} failed ({done.returncode}): {done.stderr.strip()}")
    return done.stdout


@pytest.fixture
def veth_pair():
    """Namespaces tv-<id>-a (10.0.0.1) and tv-<id>-b (10.0.0.2) joined by a veth pair."""
    uid = uuid.uuid4().hex[:8]
    ns_a, ns_b = f"tv-{uid}-a", f"tv-{uid}-b"
    if_a, if_b = f"tv{uid}a", f"tv{uid}b"
    created = []
    try:
        for ns in (ns_a, ns_b):
            _run("ip", "netns", "add", ns)
            created.append(ns)
        _run("ip", "-n", ns_a, "link", "add", "name", if_a, "type", "veth", "peer", "name", if_b)
        _run("ip", "-n", ns_a, "link", "set", if_b, "netns", ns_b)
        for ns, ifname, addr in ((ns_a, if_a, "10.0.0.1/24"), (ns_b, if_b, "10.0.0.2/24")):
            _run("ip", "-n", ns, "addr", "add", addr, "dev", ifname)
            _run("ip", "-n", ns, "link", "set", ifname, "up")
            _run("ip", "-n", ns, "link", "set", "lo", "up")
        yield (ns_a, if_a), (ns_b, if_b)
    finally:
        for ns in reversed(created):
            subprocess.run(["ip", "netns", "del", ns], capture_output=True, check=False)


def _median_rtt_ms(ns: str, dst: str) -> float:
    out = _run(
        "ip", "netns", "exec", ns, "ping", "-n", "-c", str(PINGS), "-i", "0.1", "-W", "5", dst
    )
    rtts = [float(m) for m in re.findall(r"time=([\d.]+) ms", out)]
    assert len(rtts) >= PINGS * 0.9, f"only {len(rtts)} of {PINGS} pings answered:\n{out}"
    return statistics.median(rtts)


def _add_netem_delay(ns: str, ifname: str, delay_ms: int) -> None:
    with IPRoute(netns=ns) as ipr:
        (idx,) = ipr.link_lookup(ifname=ifname)
        ipr.tc("add", "netem", index=idx, handle="1:", delay=delay_ms * 1000)


def test_netem_delay_raises_rtt(veth_pair):
    (ns_a, if_a), (ns_b, if_b) = veth_pair
    _median_rtt_ms(ns_a, "10.0.0.2")  # warm up ARP so it is not in the baseline
    base = _median_rtt_ms(ns_a, "10.0.0.2")

    _add_netem_delay(ns_a, if_a, DELAY_MS)
    _add_netem_delay(ns_b, if_b, DELAY_MS)
    qdiscs = _run("tc", "-n", ns_a, "qdisc", "show", "dev", if_a)
    assert "netem" in qdiscs and "delay 50ms" in qdiscs, qdiscs

    delayed = _median_rtt_ms(ns_a, "10.0.0.2")
    added = delayed - base
    expected = 2 * DELAY_MS
    assert abs(added - expected) <= 0.1 * expected, (
        f"netem {DELAY_MS} ms each way added {added:.1f} ms to the median RTT "
        f"({base:.2f} -> {delayed:.2f} ms), expected {expected} ms +-10%"
    )
