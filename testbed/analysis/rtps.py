"""DDS's traffic on the wire: which bytes of an RTPS datagram are the robots' messages and
which Cyclone DDS's own (`split`), for the captures' middleware metrics
(testbed.analysis.pcapmetrics).

Theory of operation. A robot's DDS participant (node/messaging/dds.py) sends RTPS over UDP,
one RTPS message per datagram: a 20-byte header ("RTPS", version, vendor, the participant's
GUID prefix), then submessages, each a 4-byte header (id, flags whose lowest bit says
little-endian, length to the next one; 0 for the last: to the datagram's end) and a body.
Each submessage is counted as one kind of the middleware's own, or as a message:

- `rtps_header`: each datagram's header; `info`: INFO_TS, INFO_DST, INFO_SRC, INFO_REPLY
  and PAD, which only say when, to whom and from where the next submessages are;
- submessages of built-in endpoints (an entity id whose kind has either top bit set: DDS's
  built-in or a vendor's): `spdp` (participant discovery), `sedp` (publications,
  subscriptions, topics), `liveliness` (participant messages), `type_lookup`, and
  `builtin_other`; their DATA, HEARTBEAT, ACKNACK and GAP alike;
- submessages of the robots' own endpoints (the `tb_goal` topic's writers and readers):
  HEARTBEAT, ACKNACK, GAP, NACK_FRAG and HEARTBEAT_FRAG are `reliability`; a DATA with
  serialized data carries one message, a GoalSample (int32 dst, int32 src,
  sequence<uint8> payload) in CDR: the sequence's bytes are the message (`payload`), the
  rest of the submessage (its header, writer and reader ids, sequence number, inline QoS,
  encapsulation, dst, src, the sequence's length, padding) is `data_headers`. A DATA
  without serialized data (a writer's unregister or dispose) is `data_without_sample`.
  A DATA whose writer and sequence number were counted before is a retransmission by
  DDS's reliability: its bytes are counted apart (`retransmitted`), not as a message;
- anything else: `other` (a vendor's submessage), or `unparsed` when it cannot be walked
  (a datagram that is not RTPS, a length past the datagram's end, a sample that is not a
  GoalSample, a DATA_FRAG of the robots' writers: a sample larger than a datagram, which
  goal messages never are).

Pure: bytes in, counts out; `seen` (the writers' sequence numbers met so far) is the
caller's, one per sender.
"""

from __future__ import annotations

import struct

from testbed.analysis.mwframing import Split

MAGIC = b"RTPS"
HEADER = 20  # "RTPS", version (2), vendor (2), GUID prefix (12)
SUB_HEADER = 4
PAD, ACKNACK, HEARTBEAT, GAP = 0x01, 0x06, 0x07, 0x08
INFO_TS, INFO_SRC, INFO_REPLY_IP4, INFO_DST, INFO_REPLY = 0x09, 0x0C, 0x0D, 0x0E, 0x0F
NACK_FRAG, HEARTBEAT_FRAG, DATA, DATA_FRAG = 0x12, 0x13, 0x15, 0x16
INFO = {PAD, INFO_TS, INFO_SRC, INFO_REPLY_IP4, INFO_DST, INFO_REPLY}
RELIABILITY = {ACKNACK, HEARTBEAT, GAP, NACK_FRAG, HEARTBEAT_FRAG}
# Where a submessage's entity ids are in its body: (reader id, writer id) offsets.
ENTITY_OFFSETS = {DATA: (4, 8), DATA_FRAG: (4, 8), **dict.fromkeys(RELIABILITY, (0, 4))}
FLAG_LITTLE, FLAG_INLINE_QOS, FLAG_DATA = 0x01, 0x02, 0x04
NOT_BUILTIN = 0xC0  # an entity kind's top bits: 00 the user's, 11 built-in, 01 a vendor's
# Built-in entities by their entity key (DDSI-RTPS 2.x, 9.3.1.3, and DDS-XTypes' type lookup).
BUILTIN_KINDS = {
    0x000100: "spdp", 0x000002: "sedp", 0x000003: "sedp", 0x000004: "sedp",
    0x000200: "liveliness", 0x000300: "type_lookup", 0x000301: "type_lookup",
}  # fmt: skip
PID_SENTINEL = 0x0001
# CDR encapsulations: (little-endian, DHEADER before the struct); XCDR2's appendable types
# (D_CDR2) have one.
ENCAPSULATIONS = {0x0000: (False, False), 0x0001: (True, False), 0x0010: (False, False),
                  0x0011: (True, False), 0x0014: (False, True), 0x0015: (True, True)}  # fmt: skip


def _entity(body: bytes, at: int) -> bytes:
    return body[at : at + 4]


def _inline_qos_end(body: bytes, at: int, little: bool) -> int | None:
    """The end of the inline QoS parameter list starting at `at` (after PID_SENTINEL)."""
    fmt = "<HH" if little else ">HH"
    while at + 4 <= len(body):
        pid, length = struct.unpack_from(fmt, body, at)
        at += 4 + length
        if pid == PID_SENTINEL:
            return at if at <= len(body) else None
    return None


def sample_bytes(body: bytes, flags: int) -> int | None:
    """The message's length inside a DATA submessage's body (a GoalSample's payload
    sequence), or None when the body holds no GoalSample it can read."""
    little = bool(flags & FLAG_LITTLE)
    if len(body) < 20:
        return None
    (to_qos,) = struct.unpack_from("<H" if little else ">H", body, 2)
    at = 4 + to_qos
    if flags & FLAG_INLINE_QOS:
        at = _inline_qos_end(body, at, little)
        if at is None:
            return None
    encapsulation = ENCAPSULATIONS.get(int.from_bytes(body[at : at + 2], "big"))
    if encapsulation is None:
        return None
    cdr_little, dheader = encapsulation
    at += 4 + (4 if dheader else 0)  # encapsulation id and options; DHEADER
    if at + 12 > len(body):
        return None
    (size,) = struct.unpack_from("<I" if cdr_little else ">I", body, at + 8)  # after dst, src
    if size > len(body) - at - 12:
        return None
    return size


def _builtin_kind(entity: bytes) -> str:
    return BUILTIN_KINDS.get(int.from_bytes(entity[:3], "big"), "builtin_other")


def submessages(datagram: bytes) -> tuple[list[tuple[int, int, bytes]], int]:
    """An RTPS datagram's submessages as (id, flags, body), and where the walk stopped (the
    datagram's length, unless a submessage runs past it); ([], 0) if it is not RTPS."""
    if len(datagram) < HEADER or not datagram.startswith(MAGIC):
        return [], 0
    out = []
    at = HEADER
    while at + SUB_HEADER <= len(datagram):
        sub_id, flags = datagram[at], datagram[at + 1]
        (length,) = struct.unpack_from("<H" if flags & FLAG_LITTLE else ">H", datagram, at + 2)
        if length == 0 and sub_id not in (PAD, INFO_TS):
            length = len(datagram) - at - SUB_HEADER  # the last one: to the datagram's end
        end = at + SUB_HEADER + length
        if end > len(datagram):
            break
        out.append((sub_id, flags, datagram[at + SUB_HEADER : end]))
        at = end
    return out, at


def split(datagram: bytes, seen: set[tuple[bytes, bytes, bytes]]) -> Split:
    """One UDP datagram's RTPS message; `seen` holds the (GUID prefix, writer, sequence
    number) of the robots' DATA counted so far, and gains this datagram's."""
    out = Split()
    subs, walked = submessages(datagram)
    out.unparsed = len(datagram) - walked
    if not walked:
        return out
    out.own("rtps_header", HEADER)
    prefix = datagram[8:HEADER]
    for sub_id, flags, body in subs:
        size = SUB_HEADER + len(body)
        if sub_id in INFO:
            out.own("info", size)
            continue
        offsets = ENTITY_OFFSETS.get(sub_id)
        if offsets is None:
            out.own("other", size)
            continue
        reader, writer = _entity(body, offsets[0]), _entity(body, offsets[1])
        entity = writer if writer.strip(b"\0") else reader
        if len(entity) < 4:
            out.unparsed += size
        elif entity[3] & NOT_BUILTIN:
            out.own(_builtin_kind(entity), size)
        elif sub_id in RELIABILITY:
            out.own("reliability", size)
        elif sub_id == DATA_FRAG:
            out.unparsed += size
        elif not flags & FLAG_DATA:
            out.own("data_without_sample", size)
        elif (prefix, writer, body[12:20]) in seen:
            out.retransmitted += size
        elif (n := sample_bytes(body, flags)) is None:
            out.unparsed += size
        else:
            seen.add((prefix, writer, body[12:20]))
            out.message(n)
            out.own("data_headers", size - n)
    return out
