"""Goal messages over Zenoh (eclipse-zenoh), peer to peer: one session per robot.

Theory of operation. Every robot opens a Zenoh session in peer mode, listening on
tcp/<its address>:<port>, with its teammates' tcp/<address>:<port> as configured `connect`
endpoints: Zenoh dials them in the background and redials a lost one with the robot's
redial backoff. Multicast scouting is off (a multicast does not cross hops on an ad hoc
network, and the robots are given their teammates anyway); gossip scouting stays on,
single-hop, as Zenoh's configuration documents it for peers that can all reach each other:
the routing daemon makes every teammate reachable over IP, so Zenoh's own multi-hop gossip
(meant for its "linkstate" routing among peers that cannot) is not wanted. Each robot
subscribes to its own key (`tb/robot/<me>`); a send is a `put` on the teammate's key
through a publisher declared reliable, with congestion control DROP: a message the link's
queue cannot take within the send timeout is dropped, never waited for longer.

`send` returns False at once while no subscriber of the teammate's key is known (no session
to it, or its declaration not received yet): Zenoh would drop such a put silently. A put
that Zenoh takes is counted as sent; a later DROP of it in the queue is not reported by
Zenoh, and so not counted as failed.

Received samples arrive on a thread of Zenoh's and wait in an Inbox (queue + eventfd), so
`fileno()` works with select. Zenoh's shared-memory transport is off: robots on one host
must talk through the emulated network, not around it.

Every interval Zenoh keeps here derives from the arguments, which node.timing has already
divided by the time scale:
  connect retry        first wait reconnect_ms[0], doubling up to reconnect_ms[1]
  link lease           LEASE_PER_RECONNECT_MAX x reconnect_ms[1] (a silent teammate's
                       session closes after it); keep-alives KEEP_ALIVES_PER_LEASE per lease
  open/accept timeout  one lease: a handshake not done by then is abandoned and redialled
  interests timeout    one lease
  wait before drop     send_timeout_ms (also for a fragmented message)
What Zenoh leaves: its runtime's native threads stay for the life of the process, shared by
every session (a second messenger adds none). `close` waits up to Zenoh's own close timeout
(a fixed 10 s in 1.10, not settable from Python) for a teammate's link whose TCP connection is
stuck (a teammate out of reach with data queued for it); a dead teammate's link (reset by its
kernel) or an idle one closes at once.
`zenoh.open` does not wait for the teammates (open.return_conditions off), so no scouting
delay applies. Ports: TCP `port` on every robot (the listener), and an ephemeral TCP port for
each session a robot dials; no UDP.
"""

from __future__ import annotations

import contextlib
import json
import logging
from collections.abc import Callable, Sequence
from typing import Any

import zenoh

from node.messaging.base import InboxMessenger

log = logging.getLogger(__name__)

KEY_PREFIX = "tb/robot"
LEASE_PER_RECONNECT_MAX = 4  # a teammate silent for 4 redial ceilings is gone (2 s at scale 1)
KEEP_ALIVES_PER_LEASE = 4  # Zenoh's default: a lost keep-alive or two does not end a session
RETRY_INCREASE_FACTOR = 2  # the redial backoff doubles, as nng's does for GoalNet
MIN_MS = 1  # Zenoh's intervals are whole ms


def key_of(k: int) -> str:
    """The key robot k subscribes to."""
    return f"{KEY_PREFIX}/{k}"


def endpoint(addr: str, port: int) -> str:
    return f"tcp/{addr}:{port}"


def zenoh_config(
    me: int,
    bind_addr: str,
    port: int,
    addr_of: Callable[[int], str],
    team: Sequence[int],
    send_timeout_ms: int,
    reconnect_ms: tuple[int, int],
) -> dict:
    """The session's configuration (Zenoh 1.x JSON5 keys), a plain dict."""
    send_timeout_ms = max(MIN_MS, int(send_timeout_ms))
    lo, hi = (max(MIN_MS, int(v)) for v in reconnect_ms)
    hi = max(lo, hi)
    lease_ms = LEASE_PER_RECONNECT_MAX * hi
    wait_before_drop_us = 1000 * send_timeout_ms
    return {
        "mode": "peer",
        "listen": {
            "endpoints": [endpoint(bind_addr, port)],
            "timeout_ms": 0,  # bind once, now
            "exit_on_failure": True,  # a robot that cannot listen says so at once
        },
        "connect": {
            "endpoints": [endpoint(addr_of(j), port) for j in team if j != me],
            "timeout_ms": -1,  # keep dialling teammates in the background ...
            "exit_on_failure": False,  # ... without holding up zenoh.open
            "retry": {
                "period_init_ms": lo,
                "period_max_ms": hi,
                "period_increase_factor": RETRY_INCREASE_FACTOR,
            },
        },
        "open": {"return_conditions": {"connect_scouted": False, "declares": False}},
        "scouting": {
            "multicast": {"enabled": False},
            "gossip": {
                "enabled": True,
                "multihop": False,
                "target": {"peer": ["peer"]},
                "autoconnect": {"peer": ["peer"]},
            },
        },
        "routing": {"interests": {"timeout": lease_ms}},
        "adminspace": {"enabled": False},
        "transport": {
            "shared_memory": {"enabled": False},
            "unicast": {"open_timeout": lease_ms, "accept_timeout": lease_ms},
            "link": {
                "protocols": ["tcp"],
                "tx": {
                    "lease": lease_ms,
                    "keep_alive": KEEP_ALIVES_PER_LEASE,
                    "queue": {
                        "congestion_control": {
                            "drop": {
                                "wait_before_drop": wait_before_drop_us,
                                "max_wait_before_drop_fragments": wait_before_drop_us,
                            }
                        }
                    },
                },
            },
        },
    }


class ZenohMessenger(InboxMessenger):
    name = "zenoh"

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        """The contract's arguments (node.messaging.base.MessengerBase)."""
        super().__init__(*args, **kwargs)
        self.config = zenoh_config(
            self.me, self.bind_addr, self.port, self.addr_of, self.team,
            self.send_timeout_ms, self.reconnect_ms,
        )  # fmt: skip
        self._publishers: dict[int, zenoh.Publisher] = {}
        self._maps = None  # the map topic on this session (map_topic())
        self._closed = False
        try:
            self._session = zenoh.open(zenoh.Config.from_json5(json.dumps(self.config)))
            self._subscriber = self._session.declare_subscriber(key_of(self.me), self._on_sample)
        except BaseException:
            self._inbox.close()
            raise

    def _on_sample(self, sample: zenoh.Sample) -> None:
        self._inbox.put(sample.payload.to_bytes())

    def _publisher(self, j: int) -> zenoh.Publisher:
        p = self._publishers.get(j)
        if p is None:
            p = self._session.declare_publisher(
                key_of(j),
                congestion_control=zenoh.CongestionControl.DROP,
                reliability=zenoh.Reliability.RELIABLE,
                express=True,  # a goal goes out at once, not batched with later ones
            )
            self._publishers[j] = p
        return p

    def connect(self, j: int) -> None:
        """Declare the publisher for teammate j (its session is dialled from the start)."""
        if not self._closed:
            self._publisher(j)

    def _send(self, j: int, data: bytes) -> bool:
        """Hand `data` to Zenoh for teammate j; False if no subscriber of j is known or the
        put failed. Never waits longer than the send timeout (congestion control DROP)."""
        if self._closed:
            return False
        try:
            p = self._publisher(j)
            # zenoh's stub says bool; it is a MatchingStatus
            if not p.matching_status.matching:  # type: ignore[attr-defined]
                return False
            p.put(data)
            return True
        except zenoh.ZError as e:
            log.debug("r%d: put to r%d failed: %s", self.me, j, e)
            return False

    def map_topic(self):
        """The robots' maps on this session (node.messaging.zenoh_maps), made on the first
        call; close() closes it."""
        if self._maps is None:
            from node.messaging.zenoh_maps import ZenohMapTopic

            self._maps = ZenohMapTopic(self._session, self.me)
        return self._maps

    def close(self) -> None:
        """Undeclare (the map topic's entities too), close the session (its callback thread
        ends), then the eventfds."""
        if self._closed:
            return
        self._closed = True
        if self._maps is not None:
            self._maps.undeclare()
        entities: list[zenoh.Subscriber[None] | zenoh.Publisher]
        entities = [self._subscriber, *self._publishers.values()]
        for e in entities:
            with contextlib.suppress(zenoh.ZError):
                e.undeclare()
        self._publishers.clear()
        with contextlib.suppress(zenoh.ZError):
            self._session.close()
        self._inbox.close()
        if self._maps is not None:
            self._maps.close()
