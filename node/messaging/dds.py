"""Goal messages over DDS (Eclipse Cyclone DDS's Python binding): one participant per robot.

Theory of operation. Each robot makes its own Cyclone DDS domain from an XML configuration
written here (never from the user's CYCLONEDDS_URI): multicast off (a multicast does not
cross hops on an ad hoc network), the teammates' addresses as the discovery peer list, and
the network interface that holds the robot's address. Participants find each other by SPDP
sent by unicast to those peers, over the routing daemon's multi-hop routes like any traffic.

One topic, `tb_goal` (GoalSample: dst, src, payload). Addressing uses DDS partitions: the
robot's reader is in partition `r<me>`, and its writer for teammate j in partition `r<j>`,
so a writer matches only the addressed teammate's reader and a message travels to that
robot alone (Cyclone filters content at the reader, so a content filter would still send
every message to every teammate). The reader drops a sample whose `dst` is not `me`.

Writers are RELIABLE with a small KEEP_LAST history and max_blocking_time = the send timeout:
a write that cannot be queued (the writer's unacknowledged data is at its limit, e.g. the
teammate stopped answering) gives up after the send timeout and `send` returns False. `send`
returns False at once while the teammate's reader is not matched (not discovered, or its
lease expired): DDS would accept such a write and deliver it to nobody. Discovery is
asymmetric: the writer may match the teammate's reader before that reader has matched the
writer; the reader then drops the first samples, and reliability resends them from the
writer's history when the match completes: only the last HISTORY_DEPTH of them.

Received samples arrive on a Cyclone thread (the reader's listener) and wait in an Inbox
(queue + eventfd), so `fileno()` works with select.

Ports (DDSI's port mapping, with Ports/Base = `port` and domain id 0 on the wire): the
robot with participant index i receives discovery on UDP port+10+2i and data on port+11+2i;
it sends from an ephemeral UDP port. In the testbed every robot has its own network stack
and index 0: UDP port+10 and port+11. The multicast ports (port, port+1) are not opened.
Within one process each messenger is Cyclone domain `me`, shown on the wire as domain 0
(Discovery/ExternalDomainId), so several robots may share a process (tests do).
`shared_stack` (not part of the messenger contract; 1 in the testbed) is how many messengers
share one network stack: indices 0..shared_stack-1 are used and pinged.

Every interval Cyclone keeps here derives from the arguments, which node.timing has already
divided by the time scale (`CycloneTimers`): Cyclone's defaults at time scale 1, where the
send timeout is 50 ms and the redial ceiling 500 ms, scaled with them.
"""

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any
from xml.sax.saxutils import quoteattr

from cyclonedds.core import DDSException, Listener, Policy, Qos
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import int32, sequence, uint8
from cyclonedds.pub import DataWriter, Publisher
from cyclonedds.sub import DataReader, Subscriber
from cyclonedds.topic import Topic

from node.messaging.base import InboxMessenger
from node.messaging.dds_common import has_readers, samples

log = logging.getLogger(__name__)

TOPIC = "tb_goal"
WIRE_DOMAIN_ID = 0  # every robot's domain as its packets name it
HISTORY_DEPTH = 8  # KEEP_LAST: goals are superseded, a short history is enough
TAKE_BATCH = 64
# DDSI's port mapping (Cyclone's defaults): offsets from Ports/Base, participant gain.
UNICAST_META_OFFSET = 10
UNICAST_DATA_OFFSET = 11
PARTICIPANT_GAIN = 2
MAX_PORT = 65535
LEASE_PER_RECONNECT_MAX = 4  # as node.messaging.zenoh: 2 s at time scale 1


@dataclass
class GoalSample(IdlStruct, typename="tb::GoalSample"):
    dst: int32
    src: int32
    payload: sequence[uint8]  # type: ignore[type-arg]  # an IDL type, subscripted at runtime


def partition_of(k: int) -> str:
    """The partition robot k's reader is in."""
    return f"r{k}"


def meta_port(port: int, index: int) -> int:
    """UDP port of participant index `index`'s unicast discovery (data is the next one)."""
    return port + UNICAST_META_OFFSET + PARTICIPANT_GAIN * index


@dataclass(frozen=True)
class CycloneTimers:
    """Cyclone's intervals in wall microseconds, from the send timeout and the redial backoff.

    At time scale 1 (send timeout 50 ms, redial ceiling 500 ms) the protocol timers are
    Cyclone's defaults (heartbeat 100 ms, min 5 ms, minsched 20 ms; NACK delay 100 ms; ACK
    delays 10 ms; retransmit merging 5 ms; auto-reschedule NACK 3 s); the heartbeat's
    ceiling is the lease. The lease is LEASE_PER_RECONNECT_MAX redial ceilings, and SPDP goes
    out once per redial ceiling (Cyclone's default would be 80% of the lease). A writer being
    deleted waits for acknowledgements at most one send timeout (close stays short)."""

    send_timeout_ms: int
    reconnect_max_ms: int

    def _send(self, ratio: float) -> int:
        return max(1, round(ratio * 1000 * self.send_timeout_ms))

    @property
    def lease_us(self) -> int:
        return LEASE_PER_RECONNECT_MAX * 1000 * self.reconnect_max_ms

    @property
    def spdp_interval_us(self) -> int:
        return 1000 * self.reconnect_max_ms

    @property
    def auto_resched_nack_us(self) -> int:
        return 6 * 1000 * self.reconnect_max_ms

    @property
    def heartbeat_us(self) -> int:
        return self._send(2.0)

    @property
    def heartbeat_min_us(self) -> int:
        return self._send(0.1)

    @property
    def heartbeat_minsched_us(self) -> int:
        return self._send(0.4)

    @property
    def nack_delay_us(self) -> int:
        return self._send(2.0)

    @property
    def ack_delay_us(self) -> int:
        return self._send(0.2)

    @property
    def retransmit_merging_us(self) -> int:
        return self._send(0.1)

    @property
    def writer_linger_us(self) -> int:
        return self._send(1.0)


def cyclone_config(
    me: int,
    bind_addr: str,
    port: int,
    addr_of: Callable[[int], str],
    team: Sequence[int],
    timers: CycloneTimers,
    shared_stack: int = 1,
) -> str:
    """The domain's Cyclone DDS XML configuration."""
    if shared_stack < 1:
        raise ValueError(f"shared_stack must be >= 1, not {shared_stack}")
    top = meta_port(port, shared_stack - 1) + 1
    if port < 1 or top > MAX_PORT:
        raise ValueError(f"DDS port base {port} puts its ports past {MAX_PORT}")
    t = timers
    peers = "".join(
        f"<Peer Address={quoteattr(f'{addr_of(j)}:{meta_port(port, i)}')} PruneDelay='inf'/>"
        for j in team
        if j != me
        for i in range(shared_stack)
    )
    # Cyclone 11.0.1 fails to take the highest index MaxAutoParticipantIndex allows: one spare.
    return f"""<CycloneDDS xmlns="https://cdds.io/config"><Domain Id="any">
<General>
  <Interfaces><NetworkInterface address={quoteattr(bind_addr)}/></Interfaces>
  <AllowMulticast>false</AllowMulticast>
</General>
<Discovery>
  <ExternalDomainId>{WIRE_DOMAIN_ID}</ExternalDomainId>
  <ParticipantIndex>auto</ParticipantIndex>
  <MaxAutoParticipantIndex>{shared_stack}</MaxAutoParticipantIndex>
  <Peers AddLocalhost="false">{peers}</Peers>
  <InitialLocatorPruneDelay>inf</InitialLocatorPruneDelay>
  <DiscoveredLocatorPruneDelay>inf</DiscoveredLocatorPruneDelay>
  <Ports><Base>{port}</Base></Ports>
  <LeaseDuration>{t.lease_us} us</LeaseDuration>
  <SPDPInterval>{t.spdp_interval_us} us</SPDPInterval>
</Discovery>
<Internal>
  <HeartbeatInterval min="{t.heartbeat_min_us} us" minsched="{t.heartbeat_minsched_us} us"
    max="{t.lease_us} us">{t.heartbeat_us} us</HeartbeatInterval>
  <NackDelay>{t.nack_delay_us} us</NackDelay>
  <AutoReschedNackDelay>{t.auto_resched_nack_us} us</AutoReschedNackDelay>
  <AckDelay>{t.ack_delay_us} us</AckDelay>
  <PreEmptiveAckDelay>{t.ack_delay_us} us</PreEmptiveAckDelay>
  <RetransmitMergingPeriod>{t.retransmit_merging_us} us</RetransmitMergingPeriod>
  <WriterLingerDuration>{t.writer_linger_us} us</WriterLingerDuration>
</Internal>
</Domain></CycloneDDS>"""


class DdsMessenger(InboxMessenger):
    name = "dds"

    def __init__(self, *args: Any, shared_stack: int = 1, **kwargs: Any) -> None:
        """The contract's arguments (node.messaging.base.MessengerBase), and how many robots
        share one process's Cyclone stack (`shared_stack`, cyclone_config)."""
        super().__init__(*args, **kwargs)
        self.misaddressed = 0  # samples that reached this reader with another dst
        send_timeout_ms = self.send_timeout_ms
        # DDS has no backoff: the reconnect ceiling
        self.timers = CycloneTimers(send_timeout_ms, self.reconnect_ms[1])
        self.config = cyclone_config(self.me, self.bind_addr, self.port, self.addr_of,
                                     self.team, self.timers, shared_stack)  # fmt: skip
        reliable = Policy.Reliability.Reliable(max_blocking_time=send_timeout_ms * 1_000_000)
        self._writer_qos = Qos(reliable, Policy.History.KeepLast(HISTORY_DEPTH))
        # The reader keeps all: the listener takes every sample as it comes, and a burst that
        # arrives while it waits for the interpreter must not overwrite its own beginning.
        self._reader_qos = Qos(reliable, Policy.History.KeepAll)
        self._writers: dict[int, tuple[Publisher, DataWriter]] = {}
        self._entities: list = []  # made here, deleted in reverse order by close()
        self._maps = None  # the map topic in this participant (map_topic())
        self._closed = False
        try:
            self._domain = self._made(Domain(self.me, self.config))
            self._participant = self._made(DomainParticipant(self.me))
            self._topic = self._made(Topic(self._participant, TOPIC, GoalSample))
            sub = self._made(
                Subscriber(self._participant, qos=Qos(Policy.Partition([partition_of(self.me)])))
            )
            self._reader = self._made(
                DataReader(
                    sub, self._topic, qos=self._reader_qos,
                    listener=Listener(on_data_available=self._on_data),
                )
            )  # fmt: skip
        except BaseException:
            self.close()
            raise

    def _made(self, entity):
        self._entities.append(entity)
        return entity

    def _on_data(self, reader: DataReader | None) -> None:
        # Bytes that are no GoalSample: one empty message, which the robot counts malformed.
        for s in samples(reader, GoalSample, TAKE_BATCH, lambda: self._inbox.put(b"")):
            if s.dst == self.me:
                self._inbox.put(bytes(s.payload))
            else:
                self.misaddressed += 1

    def _writer(self, j: int) -> DataWriter:
        w = self._writers.get(j)
        if w is None:
            pub = self._made(
                Publisher(self._participant, qos=Qos(Policy.Partition([partition_of(j)])))
            )
            w = (pub, self._made(DataWriter(pub, self._topic, qos=self._writer_qos)))
            self._writers[j] = w
        return w[1]

    def connect(self, j: int) -> None:
        """Make the writer for teammate j now, so it is matched before the first send."""
        if not self._closed:
            self._writer(j)

    def _send(self, j: int, data: bytes) -> bool:
        """Write `data` for teammate j; False if its reader is not matched or the write gave
        up after the send timeout (max_blocking_time)."""
        if self._closed:
            return False
        try:
            w = self._writer(j)
            if not has_readers(w):
                return False
            # the IDL sequence takes bytes at runtime
            w.write(GoalSample(dst=j, src=self.me, payload=data))  # type: ignore[arg-type]
            return True
        except DDSException as e:
            log.debug("r%d: write to r%d failed: %s", self.me, j, e)
            return False

    def map_topic(self):
        """The robots' maps in this participant (node.messaging.dds_maps), made on the first
        call; its entities are deleted with this messenger's, and close() closes it."""
        if self._maps is None:
            from node.messaging.dds_maps import DdsMapTopic

            self._maps = DdsMapTopic(self._participant, self.me, self.send_timeout_ms,
                                     self._made)  # fmt: skip
        return self._maps

    def close(self) -> None:
        """Delete every entity (the map topic's too), children first (the readers' listeners
        are done when their readers are deleted), then the domain (Cyclone's threads end),
        then the eventfds."""
        if self._closed:
            return
        self._closed = True
        for e in reversed(self._entities):
            # The binding's own deletion: dds_delete once, and forgotten by its registry, so
            # the garbage collector cannot delete a handle a later entity may reuse.
            e.__del__()
        self._entities.clear()
        self._writers.clear()
        self._inbox.close()
        if self._maps is not None:
            self._maps.close()
