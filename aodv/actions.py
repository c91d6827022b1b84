"""What the AODV core asks of the world: the actions it returns from every event.

Theory of operation
-------------------
The protocol core (aodv.core) never does IO; each event returns a list of these values and
the caller (the daemon, or aodv.sim's in-memory medium) carries them out in order: send a
control message to a neighbour or to the limited broadcast address, install or delete a
kernel route, release or drop buffered data packets, record a finished discovery. They are
plain slotted dataclasses (values by convention): a frozen one costs several times as much
to build, and every control message builds two or three actions.
"""

from __future__ import annotations

from dataclasses import dataclass

from aodv.packet import Message

# Decision (RREP IP TTL): a RREP travels hop by hop and is unicast to the next hop, which
# re-originates it, so any IP TTL >= 1 arrives. We send 64 so that a RREP can never be
# taken for a HELLO (IP TTL 1, RFC 6.9) by a receiver that looks at the IP TTL.
UNICAST_TTL = 64
# RFC 6.11: a RERR to several precursors goes to "the local broadcast address
# (Destination IP == 0xFFFFFFFF, TTL == 1)". HELLOs (RFC 6.9) also carry IP TTL 1.
# Decision (limited vs subnet broadcast): robots have /32 addresses and no subnet, so
# every broadcast is the limited broadcast 255.255.255.255 on wlan0.
LOCAL_TTL = 1


@dataclass(slots=True)
class Unicast:
    msg: Message
    dst: str
    ttl: int = UNICAST_TTL


@dataclass(slots=True)
class Broadcast:
    msg: Message
    ttl: int


@dataclass(slots=True)
class InstallRoute:
    dest: str
    next_hop: str
    hops: int


@dataclass(slots=True)
class DeleteRoute:
    dest: str


@dataclass(slots=True)
class ReleasePackets:
    dest: str
    packets: tuple[bytes, ...]


@dataclass(slots=True)
class DropPackets:
    dest: str
    packets: tuple[bytes, ...]


@dataclass(slots=True)
class DiscoveryDone:
    dest: str
    ok: bool
    latency: float  # first RREQ to route (or to giving up)
    round_latency: float  # the last RREQ sent to route
    repair: bool = False  # a local repair (RFC 6.12), not a discovery of our own


Action = (
    Unicast | Broadcast | InstallRoute | DeleteRoute | ReleasePackets | DropPackets | DiscoveryDone
)
