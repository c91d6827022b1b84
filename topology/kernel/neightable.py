"""The host's IPv4 neighbour (ARP) table, read and never written.

The kernel keeps one ARP table for every network namespace together, and its limit is the
initial namespace's `net.ipv4.neigh.default.gc_thresh3` (1024 by default). A send that needs
a new entry past that limit fails with ENOBUFS, which a UDP socket does not report: the
datagram is counted as sent and never leaves, and the kernel counts a `table_fulls` in
/proc/net/stat/arp_cache (per CPU, in hex). A team of n robots that speak to one another
needs about n x (n + 1) entries at once (a teammate each, and the broadcast address), so
past about 30 robots on a default host a run can lose AODV messages and map floods
silently (docs/measurements.md, "The RREQ flood of 100 robots"). The testbed does not raise
the host's limit (nothing outside its namespaces is touched); a run counts the table's
overflows during its steps and the fidelity verdict names them (testbed.run.fidelity)."""

from __future__ import annotations

ARP_STATS = "/proc/net/stat/arp_cache"
GC_THRESH3 = "/proc/sys/net/ipv4/neigh/default/gc_thresh3"


def table_fulls(path: str = ARP_STATS) -> int | None:
    """How often the ARP table has been full since boot, over all CPUs; None if unreadable."""
    try:
        with open(path) as f:
            lines = f.read().splitlines()
        column = lines[0].split().index("table_fulls")
        return sum(int(line.split()[column], 16) for line in lines[1:] if line.strip())
    except (OSError, ValueError, IndexError):
        return None


def limit(path: str = GC_THRESH3) -> int | None:
    """The ARP table's hard limit (gc_thresh3); None if unreadable."""
    try:
        with open(path) as f:
            return int(f.read().split()[0])
    except (OSError, ValueError, IndexError):
        return None
