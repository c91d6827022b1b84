"""Flooding over UDP broadcast: send to everyone reachable, each robot relays once.

Theory of operation. A flood is sent to 255.255.255.255 on `wlan0` (SO_BINDTODEVICE), so it
reaches exactly the robots currently linked to the sender. A robot that receives a flood it
has not seen before (by (origin, seq)) delivers it and, while its TTL allows, rebroadcasts it
with the TTL lowered by one; a flood seen before, or one of its own, is dropped. The
duplicate cache keeps, per origin, the highest sequence number and the recent ones below it
(floods overtake each other on different paths), so memory stays bounded.

`Flooder` owns the socket and the cache; it never blocks on send (a full buffer drops the
datagram, as a radio would).
"""

from __future__ import annotations

import contextlib
import logging
import socket
import threading
from collections import Counter

from node import wire

log = logging.getLogger(__name__)

WINDOW = 256  # sequence numbers remembered per origin below its highest


class DuplicateCache:
    def __init__(self) -> None:
        self.high: dict[int, int] = {}
        self.recent: dict[int, set[int]] = {}

    def seen(self, origin: int, seq: int) -> bool:
        """True if (origin, seq) was seen before; records it otherwise."""
        hi = self.high.get(origin)
        if hi is None:
            self.high[origin] = seq
            self.recent[origin] = {seq}
            return False
        rec = self.recent[origin]
        if seq <= hi - WINDOW or seq in rec:
            return True
        rec.add(seq)
        if seq > hi:
            self.high[origin] = seq
            if len(rec) > 2 * WINDOW:
                self.recent[origin] = {s for s in rec if s > seq - WINDOW}
        return False


class Flooder:
    def __init__(self, me: int, port: int, iface: str | None = "wlan0", ttl: int = 16):
        self.me = me
        self.port = port
        self.ttl = ttl
        self.seq = 0
        self.cache = DuplicateCache()
        self.cache_lock = threading.Lock()  # the inbox relays while the timer originates
        self.counts: Counter[str] = Counter()
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4 << 20)
        if iface:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_BINDTODEVICE, iface.encode())
        s.bind(("0.0.0.0", port))
        s.setblocking(False)
        self.sock = s
        self.dest = ("255.255.255.255", port)

    def fileno(self) -> int:
        return self.sock.fileno()

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
        h = wire.FloodHeader(kind, self.ttl, self.me, self.seq, step)
        with self.cache_lock:
            self.cache.seen(self.me, self.seq)
        self._send(wire.pack_flood(h, payload))
        return self.seq

    def receive(self) -> list[tuple[wire.FloodHeader, bytes]]:
        """Drain the socket: new floods (header, payload), relayed on the way."""
        return [wire.unpack_flood(data) for data in self.receive_raw()]

    def receive_raw(self) -> list[bytes]:
        """Drain the socket: new floods as they arrived (wire form), relayed on the way.

        Most datagrams are copies of a flood already seen (every neighbour relays it): the
        duplicate check reads the header fields only, nothing else is built for them."""
        out = []
        recvfrom, seen, me = self.sock.recvfrom, self.cache.seen, self.me
        while True:
            try:
                data, _ = recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                return out
            try:
                ttl, origin, seq = wire.flood_ids(data)
            except ValueError as e:
                self.counts["malformed"] += 1
                log.debug("dropped malformed flood: %s", e)
                continue
            with self.cache_lock:
                dup = origin == me or seen(origin, seq)
            if dup:
                self.counts["duplicate"] += 1
                continue
            if ttl > 1:
                self._send(wire.with_ttl(data, ttl - 1))
                self.counts["relayed"] += 1
            out.append(data)

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self.sock.close()
