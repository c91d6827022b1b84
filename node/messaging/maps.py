"""The robots' maps over the middleware's publish/subscribe (`--maps pubsub`): `MapTopic`.

Theory of operation. By default a robot floods its map over UDP broadcast (node.flood, the
paper's design). A ROS 2 team would instead publish it on a topic of its middleware, and
that is what `--maps pubsub` does, with Zenoh or DDS (PUBSUB_MIDDLEWARES): every
`map_period` steps each robot publishes its map on one topic and subscribes to its
teammates'. The map is the same message a flood carries (node.wire: the flood header with
the robot as origin and sender, a TTL of 1, no neighbours; then the map, a delta or the
whole local map, as for floods), so what arrives goes into the robot's inbox as a flood does
and the merge and everything after it are unchanged. The display (robot N+1) subscribes too,
and publishes its beacon on the same topic.

A `MapTopic` keeps the Flooder's interface (originate, fileno, receive_raw, receive, counts,
stats, close), so the robot and the display take either without asking which. It lives on
the session (Zenoh) or participant (DDS) of the robot's goal messenger, one per robot as a
ROS 2 node has one: the messenger makes it (`map_topic()`) and closes it with itself.

What this changes in the network (docs/middleware.md, "Maps over publish/subscribe"): the
middleware sends each map to each subscriber by unicast, end to end over the routing
daemon's multi-hop routes (every teammate is a configured peer), instead of one broadcast
relayed by the robots on the way; there is no self-pruning, and a robot relays nobody's
maps.

Publishing is bounded like a goal send: Zenoh's congestion control DROP and DDS's
max_blocking_time, both the send timeout. A subclass provides `_publish(data) -> bool` and
hands what arrives to `_arrived(data)` from its middleware's thread.
"""

from __future__ import annotations

import logging
import time
from collections import Counter

from node import wire
from node.argsdecl import MAPS as MAPS
from node.argsdecl import PUBSUB_MIDDLEWARES as PUBSUB_MIDDLEWARES
from node.argsdecl import maps_refusal
from node.mapstats import MapStats
from node.messaging import DEFAULT_MAPS, REGISTRY
from node.messaging.inbox import Inbox

log = logging.getLogger(__name__)

DEFAULT = DEFAULT_MAPS
# The module of each middleware's map topic (what a process may import ahead of using it),
# from the registry: the middlewares that have one are those `--maps pubsub` can go with
# (node.argsdecl's PUBSUB_MIDDLEWARES, and its `maps_refusal`, declared with the parameters).
refusal = maps_refusal
MODULES = {name: e.map_topic for name, e in REGISTRY.items() if e.map_topic is not None}


class MapTopic:
    """Maps published and received over a middleware; the Flooder's interface."""

    def __init__(self, me: int) -> None:
        self.me = me
        self.seq = 0
        self.counts: Counter[str] = Counter()  # malformed, own (a sample of ours came back)
        self.stats = MapStats("pubsub")
        self._inbox = Inbox()
        self._closed = False

    def _publish(self, data: bytes) -> bool:
        raise NotImplementedError

    def _arrived(self, data: bytes) -> None:
        """From the middleware's thread: a teammate's map (or beacon) in flood form."""
        self._inbox.put(data)

    def fileno(self) -> int:
        return self._inbox.fileno()

    def originate(self, kind: int, step: int, payload: bytes) -> int:
        """Publish a map (or the display's beacon) of ours; returns its sequence number."""
        self.seq += 1
        h = wire.FloodHeader(kind, 1, self.me, self.seq, step, self.me, ())
        data = wire.pack_flood(h, payload)
        t0 = time.monotonic()
        ok = not self._closed and self._publish(data)
        if kind == wire.KIND_MAP:
            self.stats.note_publish(len(data), ok, time.monotonic() - t0)
        if not ok:
            self.counts["send_failed"] += 1
        return self.seq

    def receive_raw(self) -> list[bytes]:
        """Every message waiting now, in flood form; never blocks. A message that is not a
        flood of a teammate's is counted as malformed and dropped."""
        out = []
        for data in self._inbox.take_all():
            try:
                _, origin, _, _ = wire.flood_ids(data)
                wire.flood_neighbours(data)
            except ValueError as e:
                self.counts["malformed"] += 1
                log.debug("dropped a malformed map message: %s", e)
                continue
            if origin == self.me:
                self.counts["own"] += 1
                continue
            if data[4] == wire.KIND_MAP:
                self.stats.note_receive(origin, len(data))
            out.append(data)
        return out

    def receive(self) -> list[tuple[wire.FloodHeader, bytes]]:
        return [wire.unpack_flood(data) for data in self.receive_raw()]

    def close(self) -> None:
        """Stop publishing and free the inbox (the messenger has removed the topic's
        entities first, so nothing arrives any more); idempotent."""
        if not self._closed:
            self._closed = True
            self._inbox.close()
