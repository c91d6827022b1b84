"""Maps over DDS (`--maps pubsub --middleware dds`): `DdsMapTopic`.

One topic, `tb_map` (MapSample: src, payload), keyed by the sender, in the default
partition: every robot's writer matches every teammate's reader (and the display's). The
entities are made in the participant of the robot's goal messenger (node.messaging.dds),
which deletes them with its own.

Quality of service, set as a ROS 2 map topic is (nav2's map server: reliable, keep last 1),
but volatile:
- RELIABLE: a map is several kilobytes, several UDP fragments; best effort loses the whole
  map for one lost fragment, reliability repairs it.
- KEEP_LAST 1 (per sender, the key): a newer map replaces one not yet acknowledged, so a
  teammate out of reach never holds a queue of stale maps and a write never waits for its
  acknowledgements. What that costs: a delta replaced before it was acknowledged is lost,
  as a lost flood is; a teammate heard again after reach_steps gets the whole map (the
  robot's reunion rule), and every full_period steps everyone does.
- VOLATILE, not ROS 2's transient local: the samples are mostly deltas, and a late joiner
  replayed the last delta would learn a sliver; it gets the whole map by the reunion rule.
- max_blocking_time = the send timeout, as for goals: a write that Cyclone throttles (its
  unacknowledged data at the writer's limit) gives up then, and counts as failed.
- IgnoreLocal participant: a robot does not receive its own maps.

A write while no reader is matched is not made (DDS would deliver it to nobody) and counts
as failed. Cyclone sends each sample to each matched reader's unicast locator, over the
routing daemon's routes; nobody relays it.
"""

import logging
from collections.abc import Callable
from dataclasses import dataclass

from cyclonedds.core import DDSException, Listener, Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.annotations import key
from cyclonedds.idl.types import int32, sequence, uint8
from cyclonedds.pub import DataWriter, Publisher
from cyclonedds.sub import DataReader, Subscriber
from cyclonedds.topic import Topic

from node.messaging.dds_common import has_readers, samples
from node.messaging.maps import MapTopic

log = logging.getLogger(__name__)

MAP_TOPIC = "tb_map"
TAKE_BATCH = 16


@dataclass
class MapSample(IdlStruct, typename="tb::MapSample"):
    src: int32
    key("src")
    payload: sequence[uint8]  # type: ignore[type-arg]  # an IDL type, subscripted at runtime


def map_qos(send_timeout_ms: int) -> Qos:
    """The writers' and readers' QoS (see the module's docstring)."""
    return Qos(
        Policy.Reliability.Reliable(max_blocking_time=send_timeout_ms * 1_000_000),
        Policy.History.KeepLast(1),
        Policy.Durability.Volatile,
        Policy.IgnoreLocal.Participant,
    )


class DdsMapTopic(MapTopic):
    def __init__(
        self, participant: DomainParticipant, me: int, send_timeout_ms: int, made: Callable
    ) -> None:
        """`made` registers each entity with the messenger, which deletes them."""
        super().__init__(me)
        qos = map_qos(send_timeout_ms)
        try:
            topic = made(Topic(participant, MAP_TOPIC, MapSample))
            self._writer = made(DataWriter(made(Publisher(participant)), topic, qos=qos))
            listener = Listener(on_data_available=self._on_data)
            made(DataReader(made(Subscriber(participant)), topic, qos=qos, listener=listener))
        except BaseException:
            super().close()
            raise

    def _on_data(self, reader: DataReader | None) -> None:
        # Bytes that are no MapSample: one empty map message, counted malformed.
        for s in samples(reader, MapSample, TAKE_BATCH, lambda: self._arrived(b"")):
            self._arrived(bytes(s.payload))

    def _publish(self, data: bytes) -> bool:
        try:
            if not has_readers(self._writer):
                return False
            # the IDL sequence takes bytes at runtime
            self._writer.write(MapSample(src=self.me, payload=data))  # type: ignore[arg-type]
            return True
        except DDSException as e:
            log.debug("r%d: map write failed: %s", self.me, e)
            return False
