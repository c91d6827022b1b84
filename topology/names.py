"""Names are a contract between the code that creates kernel objects and the code that cleans.

Every namespace a testbed creates carries the testbed's name: `tb-NAME-m` is the medium,
`tb-NAME-rK` is robot K. `testbed clean` finds leftovers by `NAMESPACE_PATTERN` and nothing
else, so the two sides share this module. Interfaces live only inside those namespaces (none in
the host), so their names need no run id; they fit in 15 characters for up to 1000 robots.
"""

import re

PREFIX = "tb"
# Matched whole (fullmatch), never with `^...$`: `$` also matches before a final newline, so
# "pqn\n" would pass and make namespaces that `testbed clean` cannot see. ASCII digits only.
NAME_PATTERN = re.compile(r"[a-z][a-z0-9]{0,9}")
NAMESPACE_PATTERN = re.compile(rf"{PREFIX}-(?P<name>[a-z][a-z0-9]{{0,9}})-(?P<role>m|r[0-9]+)")
MAX_ROBOTS = 1000

# The ad hoc network every robot address is in (robot_addr): NET_OCTETS.hi.lo, with lo from 1
# to ADDRS_PER_OCTET. The C++ robot takes both from here (node.constgen).
NET_OCTETS = (10, 0)
ADDRS_PER_OCTET = 254
NETWORK = f"{NET_OCTETS[0]}.{NET_OCTETS[1]}.0.0/16"
_NET_PARTS = [str(o) for o in NET_OCTETS]  # an address's first two parts, as split

# Inside a robot namespace.
ROBOT_IFACE = "wlan0"

# The ns3-wifi medium's per-frame relay lag (topology.radio.ns3wifi writes it, in the testbed's run
# directory and a run's; testbed.analysis.relaylag reads it).
LAG_FILE = "relay-lag.bin"


def check_name(name: str) -> str:
    """Return `name` if it is a valid testbed name, else raise ValueError."""
    if not isinstance(name, str) or not NAME_PATTERN.fullmatch(name):
        raise ValueError(
            f"testbed name {str(name)[:40]!r} must be 1-10 characters, lowercase letters and "
            "digits, starting with a letter"
        )
    return name


ROBOT_REF_PATTERN = re.compile(r"[rR]?([0-9]{1,4})")


def parse_robot_ref(text: str) -> int:
    """Robot K from `K` or `rK` (ASCII digits, 1..MAX_ROBOTS), else ValueError saying so."""
    m = ROBOT_REF_PATTERN.fullmatch(text)
    if m is None or not 1 <= int(m[1]) <= MAX_ROBOTS:
        raise ValueError(f"robot {text[:20]!r} must be K or rK with K >= 1 and <= {MAX_ROBOTS}")
    return int(m[1])


def medium_ns(name: str) -> str:
    return f"{PREFIX}-{name}-m"


def robot_ns(name: str, k: int) -> str:
    return f"{PREFIX}-{name}-r{k}"


def parse_ns(ns: str) -> tuple[str, str] | None:
    """(testbed name, role) of one of our namespaces, or None for anything else."""
    m = NAMESPACE_PATTERN.fullmatch(ns)
    return (m["name"], m["role"]) if m else None


def robot_addr(k: int) -> str:
    """Robot k (1-based) is 10.0.0.k; past 254 the third octet counts up (10.0.1.1, ...)."""
    if not 1 <= k <= MAX_ROBOTS:
        raise ValueError(f"robot number {k} out of range 1..{MAX_ROBOTS}")
    hi, lo = divmod(k - 1, ADDRS_PER_OCTET)
    return f"{NET_OCTETS[0]}.{NET_OCTETS[1]}.{hi}.{lo + 1}"


def robot_of_addr(addr: str) -> int | None:
    """Inverse of robot_addr, None if addr is not a robot address."""
    parts = addr.split(".")
    if len(parts) != 4 or parts[:2] != _NET_PARTS:
        return None
    try:
        hi, lo = int(parts[2]), int(parts[3])
    except ValueError:
        return None
    if not 1 <= lo <= ADDRS_PER_OCTET or hi < 0:
        return None
    k = hi * ADDRS_PER_OCTET + lo
    return k if k <= MAX_ROBOTS else None


# Inside the medium namespace: robot K's bridge and the port that leads to its wlan0.
def bridge(k: int) -> str:
    return f"br{k}"


def robot_port(k: int) -> str:
    return f"rp{k}"


def link_end(i: int, j: int) -> str:
    """The end of link i-j that sits in bridge i; frames leaving through it go i -> j."""
    return f"l{i}x{j}"


LINK_END_PATTERN = re.compile(r"l([0-9]+)x([0-9]+)")


def parse_link_end(ifname: str) -> tuple[int, int] | None:
    m = LINK_END_PATTERN.fullmatch(ifname)
    return (int(m[1]), int(m[2])) if m else None
