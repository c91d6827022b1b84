"""Maps over Zenoh (`--maps pubsub --middleware zenoh`): `ZenohMapTopic`.

Each robot publishes its maps on its own key, `tb/map/<me>`, and subscribes to `tb/map/*`:
the key names the sender, as a ROS 2 topic per robot would (`/r2/map`), and one
subscription takes every teammate's, including a teammate that joins late. The publisher is
declared on the session of the robot's goal messenger (node.messaging.zenoh), reliable,
with congestion control DROP: a map the link's queue cannot take within the send timeout
is dropped, as a goal is (the timer thread that publishes never waits longer). Not
express: a map may ride in a batch with other messages, a few hundred microseconds matter
not to it. Publisher and subscriber are REMOTE only: a robot does not receive its own maps.

A put while no subscriber is known is not sent (Zenoh would drop it unseen) and counts as
failed. Zenoh's own routing carries each map to each subscriber over the session to it, a
unicast TCP link over the routing daemon's routes; nobody relays it.
"""

from __future__ import annotations

import contextlib
import logging

import zenoh

from node.messaging.maps import MapTopic

log = logging.getLogger(__name__)

MAP_PREFIX = "tb/map"


def map_key(k: int) -> str:
    """The key robot k publishes its maps on."""
    return f"{MAP_PREFIX}/{k}"


class ZenohMapTopic(MapTopic):
    def __init__(self, session: zenoh.Session, me: int) -> None:
        super().__init__(me)
        try:
            self._publisher = session.declare_publisher(
                map_key(me),
                congestion_control=zenoh.CongestionControl.DROP,
                reliability=zenoh.Reliability.RELIABLE,
                allowed_destination=zenoh.Locality.REMOTE,
            )
            self._subscriber = session.declare_subscriber(
                f"{MAP_PREFIX}/*", self._on_sample, allowed_origin=zenoh.Locality.REMOTE
            )
        except BaseException:
            super().close()
            raise

    def _on_sample(self, sample: zenoh.Sample) -> None:
        self._arrived(sample.payload.to_bytes())

    def _publish(self, data: bytes) -> bool:
        try:
            # zenoh's stub says bool; it is a MatchingStatus
            if not self._publisher.matching_status.matching:  # type: ignore[attr-defined]
                return False
            self._publisher.put(data)
            return True
        except zenoh.ZError as e:
            log.debug("r%d: map put failed: %s", self.me, e)
            return False

    def undeclare(self) -> None:
        """Undeclare the publisher and the subscriber (the messenger does, before it closes
        the session)."""
        for e in (self._subscriber, self._publisher):
            with contextlib.suppress(zenoh.ZError):
                e.undeclare()
