"""Flooding over UDP broadcast: every robot reachable gets each flood once or more.

Theory of operation. A flood is sent to 255.255.255.255 on `wlan0` (SO_BINDTODEVICE), so it
reaches exactly the robots currently linked to the sender. A robot that receives a flood it
has not seen before (by (origin, seq)) delivers it and, while its TTL allows, may rebroadcast
it with the TTL lowered by one; a flood seen before, or one of its own, is dropped. The
duplicate cache keeps, per origin, the highest sequence number and the recent ones below it
(floods overtake each other on different paths), so memory stays bounded.

Sequence numbers are believed only within a window, as RFC 3561 (section 6.1) compares its
own: the difference of two numbers is taken as a signed 32-bit number, so they may wrap
around, and every origin starts from 0 (its floods are numbered 1, 2, ...). A number more than
SEQ_WINDOW ahead of (or behind) the highest one believed from its origin is not believed: the
flood is counted (`forged`, and in `malformed`), dropped, and changes nothing, so that one
forged flood (origin 2, sequence 2^32 - 1) cannot make origin 2's real floods look old. A
number within the window is believed: floods carry no signature, so a forger that stays
within it is not told apart (docs/robot-contract.md, section 2).

Whether a robot rebroadcasts is the flooding *mode*:

- "blind": every robot relays every new flood once (simple flooding). In a dense team each
  robot then receives a copy from every neighbour: n robots in range of each other send n
  copies of each flood and receive n(n-1), the broadcast storm of Ni et al. (MobiCom 1999).
- "pruned" (the default): self-pruning (Lim and Kim, "Flooding in wireless ad hoc networks",
  Computer Communications 24, 2001). Every copy carries its sender and the neighbours the
  sender heard recently; a robot relays a new flood only if it hears a neighbour that the
  copy's sender does not (so someone may still be without it). A robot's neighbours are the
  senders of the datagrams it received within `hold` seconds: every robot floods its map
  every few steps, so the table follows the links. A team all in range of each other then
  sends one copy per flood instead of n. The cost: a neighbour that appeared in the last
  `hold` seconds, or one the sender lost in that time, may miss a flood that blind flooding
  would have brought; the map floods are periodic and whole maps follow reunions.

`Flooder` owns the socket, the cache and the neighbour table; it never blocks on send (a full
buffer drops the datagram, as a radio would). Its `stats` count the maps it originated and
delivered (node.mapstats), as the publish/subscribe transport's do (node.messaging.maps).
"""

from __future__ import annotations

import contextlib
import logging
import socket
import threading
import time
from collections import Counter

from node import wire
from node.argsdecl import FLOODS
from node.mapstats import MapStats

log = logging.getLogger(__name__)

WINDOW = 256  # sequence numbers remembered per origin below its highest
# How far from the highest sequence number believed from an origin (0 before any) another is
# believed (docs/robot-contract.md, section 2): more than any run can send (an origin floods
# at most once a step, a run has at most 10,000,000 steps), far less than half the number
# space, so that wrap-around comparison stays meaningful.
SEQ_WINDOW = 1 << 24
MODES = FLOODS  # declared with the robot's parameters (node.argsdecl)
TTL = 16  # hops a flood travels at most
SOCKET_BUFFER = 4 << 20  # the flood socket's receive and send buffers, bytes
NEW, DUPLICATE, FORGED = "new", "duplicate", "forged"


def seq_diff(a: int, b: int) -> int:
    """a - b as a signed 32-bit number (RFC 3561, 6.1): > 0 when a is the newer."""
    d = (a - b) & 0xFFFFFFFF
    return d - (1 << 32) if d & 0x80000000 else d


class DuplicateCache:
    """Per origin, the highest sequence number believed and those seen within WINDOW below."""

    def __init__(self) -> None:
        self.high: dict[int, int] = {}
        self.recent: dict[int, set[int]] = {}

    def check(self, origin: int, seq: int) -> str:
        """NEW (recorded), DUPLICATE (seen, or older than the remembered ones) or FORGED (more
        than SEQ_WINDOW from the highest believed: nothing recorded). `seq`: 0 .. 2^32 - 1."""
        hi = self.high.get(origin, 0)
        d = seq_diff(seq, hi)
        if d > SEQ_WINDOW or d < -SEQ_WINDOW:
            return FORGED
        rec = self.recent.setdefault(origin, set())
        if d <= -WINDOW or seq in rec:
            return DUPLICATE
        rec.add(seq)
        if d > 0:
            self.high[origin] = seq
            if len(rec) > 2 * WINDOW:
                self.recent[origin] = {s for s in rec if seq_diff(s, seq) > -WINDOW}
        return NEW

    def seen(self, origin: int, seq: int) -> bool:
        """True if (origin, seq) is not a new flood (seen before, or not believed)."""
        return self.check(origin, seq) != NEW


class Flooder:
    def __init__(
        self,
        me: int,
        port: int,
        iface: str | None = "wlan0",
        ttl: int = TTL,
        mode: str = "pruned",
        hold: float = 1.5,
        clock=time.monotonic,
    ):
        if mode not in MODES:
            raise ValueError(f"unknown flooding mode {mode!r} (one of {', '.join(MODES)})")
        self.me = me
        self.port = port
        self.ttl = ttl
        self.mode = mode
        self.hold = hold
        self.clock = clock
        self.seq = 0
        self.cache = DuplicateCache()
        self.cache_lock = threading.Lock()  # the inbox relays while the timer originates
        self.heard: dict[int, float] = {}  # neighbour -> when a datagram from it last came
        self.counts: Counter[str] = Counter()
        self.stats = MapStats("flood")
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, SOCKET_BUFFER)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SOCKET_BUFFER)
        if iface:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_BINDTODEVICE, iface.encode())
        s.bind(("0.0.0.0", port))
        s.setblocking(False)
        self.sock = s
        self.dest = ("255.255.255.255", port)

    def fileno(self) -> int:
        return self.sock.fileno()

    def neighbours(self, now: float | None = None) -> list[int]:
        """The robots heard within `hold` seconds."""
        now = self.clock() if now is None else now
        return [k for k, t in self.heard.items() if now - t <= self.hold]

    def _send(self, data: bytes) -> bool:
        try:
            self.sock.sendto(data, self.dest)
            return True
        except (BlockingIOError, OSError) as e:
            self.counts["send_failed"] += 1
            log.debug("flood send failed: %s", e)
            return False

    def originate(self, kind: int, step: int, payload: bytes) -> int:
        """Flood a new message of ours; returns its sequence number."""
        self.seq += 1
        with self.cache_lock:
            self.cache.seen(self.me, self.seq)
            nb = tuple(self.neighbours())
        h = wire.FloodHeader(kind, self.ttl, self.me, self.seq, step, self.me, nb)
        data = wire.pack_flood(h, payload)
        t0 = time.monotonic()
        ok = self._send(data)
        if kind == wire.KIND_MAP:
            self.stats.note_publish(len(data), ok, time.monotonic() - t0)
        return self.seq

    def receive(self) -> list[tuple[wire.FloodHeader, bytes]]:
        """Drain the socket: new floods (header, payload), relayed on the way."""
        return [wire.unpack_flood(data) for data in self.receive_raw()]

    def must_relay(self, sender: int, origin: int, covered, now: float) -> bool:
        """The relay rule for a new flood whose copy came from `sender` (cache lock held)."""
        if self.mode == "blind":
            return True
        skip = set(covered)
        skip.update((sender, origin))
        return any(k not in skip for k in self.neighbours(now))

    def receive_raw(self) -> list[bytes]:
        """Drain the socket: new floods as they arrived (wire form), relayed on the way.

        A copy of a flood already seen costs a header read and a dictionary update (its
        sender is a neighbour); nothing else is built for it."""
        out: list[bytes] = []
        recvfrom, check, me, heard = self.sock.recvfrom, self.cache.check, self.me, self.heard
        now = self.clock()
        while True:
            try:
                data, _ = recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                return out
            try:
                ttl, origin, seq, sender = wire.flood_ids(data)
                covered, _ = wire.flood_neighbours(data)
            except ValueError as e:
                self.counts["malformed"] += 1
                log.debug("dropped malformed flood: %s", e)
                continue
            if sender != me:
                heard[sender] = now
            with self.cache_lock:
                verdict = DUPLICATE if origin == me else check(origin, seq)
                if verdict == FORGED:
                    self.counts["forged"] += 1
                    self.counts["malformed"] += 1
                    log.debug("dropped a flood of %d with a sequence number not believed: %d",
                              origin, seq)  # fmt: skip
                    continue
                if verdict == DUPLICATE:
                    self.counts["duplicate"] += 1
                    continue
                relay = ttl > 1 and self.must_relay(sender, origin, covered, now)
                nb = self.neighbours(now) if relay else ()
            if relay:
                self._send(wire.relayed(data, ttl - 1, me, nb))
                self.counts["relayed"] += 1
            elif ttl > 1:
                self.counts["pruned"] += 1
            if data[4] == wire.KIND_MAP:
                self.stats.note_receive(origin, len(data))
            out.append(data)

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self.sock.close()
