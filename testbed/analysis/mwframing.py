"""The middlewares' framing on the wire: which bytes of a TCP stream are the robots' messages
and which the middleware's own (`split`), for the captures' middleware metrics
(testbed.analysis.pcapmetrics; DDS, over UDP, is walked by testbed.analysis.rtps).

Theory of operation. A robot's goal messages travel inside its middleware's protocol, over
TCP on the goal port (docs/middleware.md). Given one direction of one connection, as the
sender's capture holds it (reassembled in sequence order), the middleware's framing is
walked from the connection's first byte:

- nanomsg (SP over TCP, nng): an 8-byte protocol header (0x00 'S' 'P' 0x00, the protocol,
  two reserved bytes) from each side, then each message as a 64-bit length and the body.
- ZeroMQ (ZMTP 3): a 64-byte greeting from each side, then frames: a flags byte (MORE,
  LONG, COMMAND), a size of 1 byte (8 with LONG), the body. Commands (READY, and PING
  where heartbeats are on) are the middleware's own; so is the empty delimiter frame
  before a REQ socket's request and a REP socket's empty reply (zeromq-reqrep).
- Zenoh (over TCP): batches, each after its length (2 bytes, little-endian), the first of
  a connection an INIT. A batch holds transport messages (INIT and OPEN, the handshake;
  KEEP_ALIVE; CLOSE; FRAME, holding network messages: declarations, interests, and a put's
  PUSH; FRAGMENT), in a binary encoding this walk does not decode. The robots' messages are
  found in the batches by their bodies: a JSON object whose first key is "k" (node/wire.py
  writes every message so) immediately after its length as a Zenoh varint (LEB128), as a
  PUT's payload is written. A batch is classed by its first transport message; a message
  cut into FRAGMENTs (one larger than a batch: 65,535 bytes) would not be found.

What is the middleware's own is counted in `protocol`, by kind (`kinds`: how many and how
many bytes), the robots' message bodies in `payload`, and bytes that cannot be walked (a
stream whose start was not captured, a gap, a frame cut short at the capture's end) in
`unparsed`. Pure: bytes in, counts out.
"""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass, field

SP_MAGIC = b"\x00SP\x00"
SP_HEADER = 8
SP_LENGTH = struct.Struct("!Q")
ZMTP_GREETING = 64
ZMTP_MORE, ZMTP_LONG, ZMTP_COMMAND = 0x01, 0x02, 0x04
ZENOH_LENGTH = 2  # each batch's length, little-endian
ZENOH_INIT, ZENOH_FRAME, ZENOH_ID_MASK = 0x01, 0x05, 0x1F
# A batch's kind by its first transport message's id (zenoh-protocol's transport ids).
ZENOH_BATCH_KINDS = {0x00: "oam", 0x01: "handshake", 0x02: "handshake", 0x03: "close",
                     0x04: "keep_alive", 0x05: "frames", 0x06: "fragments"}  # fmt: skip
MESSAGE_START = b'{"k"'  # node/wire.py: every goal and re-plan message begins so


@dataclass
class Split:
    messages: int = 0  # the robots' messages (a multipart ZeroMQ message is one)
    payload: int = 0  # their bytes
    protocol: int = 0  # the middleware's own bytes: headers, greetings, commands, replies
    unparsed: int = 0  # bytes that could not be walked
    retransmitted: int = 0  # a message sent again by the middleware itself (DDS), not counted
    kinds: dict[str, list[int]] = field(default_factory=dict)  # protocol by kind: [n, bytes]

    def own(self, kind: str, nbytes: int, n: int = 1) -> None:
        """`nbytes` of the middleware's own, of `kind` (`n` of them)."""
        self.protocol += nbytes
        k = self.kinds.setdefault(kind, [0, 0])
        k[0] += n
        k[1] += nbytes

    def message(self, nbytes: int) -> None:
        self.messages += 1
        self.payload += nbytes

    def add(self, other: Split) -> None:
        self.messages += other.messages
        self.payload += other.payload
        self.protocol += other.protocol
        self.unparsed += other.unparsed
        self.retransmitted += other.retransmitted
        for kind, (n, nbytes) in other.kinds.items():
            k = self.kinds.setdefault(kind, [0, 0])
            k[0] += n
            k[1] += nbytes


def split_sp(stream: bytes) -> Split:
    """One direction of a nanomsg (SP over TCP) connection."""
    out = Split()
    if not stream.startswith(SP_MAGIC) or len(stream) < SP_HEADER:
        out.unparsed = len(stream)
        return out
    out.own("sp_header", SP_HEADER)
    at = SP_HEADER
    while at + SP_LENGTH.size <= len(stream):
        (size,) = SP_LENGTH.unpack_from(stream, at)
        if size > len(stream) - at - SP_LENGTH.size:
            break
        out.own("length_prefix", SP_LENGTH.size)
        out.message(size)
        at += SP_LENGTH.size + size
    out.unparsed = len(stream) - at
    return out


def split_zmtp(stream: bytes) -> Split:
    """One direction of a ZeroMQ (ZMTP 3) connection."""
    out = Split()
    greeting_ok = (
        len(stream) >= ZMTP_GREETING and stream[0] == 0xFF and stream[9] == 0x7F and stream[10] >= 3
    )
    if not greeting_ok:
        out.unparsed = len(stream)
        return out
    out.own("greeting", ZMTP_GREETING)
    at = ZMTP_GREETING
    while at + 2 <= len(stream):
        flags = stream[at]
        head = 9 if flags & ZMTP_LONG else 2
        if at + head > len(stream):
            break
        size = int.from_bytes(stream[at + 1 : at + head], "big")
        if size > len(stream) - at - head:
            break
        if flags & ZMTP_COMMAND:
            out.own("command", head + size)
        elif size == 0:
            out.own("empty_frame", head)  # REQ/REP's delimiter, REP's empty reply
        else:
            out.own("frame_header", head)
            out.payload += size
            if not flags & ZMTP_MORE:
                out.messages += 1
        at += head + size
    out.unparsed = len(stream) - at
    return out


def _leb128(n: int) -> bytes:
    out = bytearray()
    while True:
        out.append((n & 0x7F) | (0x80 if n > 0x7F else 0))
        n >>= 7
        if not n:
            return bytes(out)


def find_messages(batch: bytes) -> list[tuple[int, int]]:
    """The robots' messages in one Zenoh batch, as (start, length): each a JSON object
    beginning `{"k"` that follows its own length as a varint (LEB128)."""
    out = []
    at = batch.find(MESSAGE_START)
    while at >= 0:
        end = at + 1
        try:
            body, n = json.JSONDecoder().raw_decode(batch[at:].decode("latin-1"))
        except ValueError:
            body, n = None, 0
        prefix = _leb128(n)
        if isinstance(body, dict) and at >= len(prefix) and batch[at - len(prefix) : at] == prefix:
            out.append((at, n))
            end = at + n
        at = batch.find(MESSAGE_START, end)
    return out


def split_zenoh(stream: bytes) -> Split:
    """One direction of a Zenoh connection over TCP."""
    out = Split()
    starts_ok = len(stream) > ZENOH_LENGTH and stream[ZENOH_LENGTH] & ZENOH_ID_MASK == ZENOH_INIT
    if not starts_ok:
        out.unparsed = len(stream)
        return out
    at = 0
    while at + ZENOH_LENGTH < len(stream):
        size = int.from_bytes(stream[at : at + ZENOH_LENGTH], "little")
        if size == 0 or size > len(stream) - at - ZENOH_LENGTH:
            break
        batch = stream[at + ZENOH_LENGTH : at + ZENOH_LENGTH + size]
        out.own("batch_length", ZENOH_LENGTH)
        found = find_messages(batch)
        for _, n in found:
            out.message(n)
        rest = size - sum(n for _, n in found)
        if found:
            out.own("message_headers", rest, len(found))  # FRAME, PUSH and PUT around each
        else:
            out.own(ZENOH_BATCH_KINDS.get(batch[0] & ZENOH_ID_MASK, "other"), rest)
        at += ZENOH_LENGTH + size
    out.unparsed = len(stream) - at
    return out


FRAMINGS = {"sp": split_sp, "zmtp": split_zmtp, "zenoh": split_zenoh}


def split(framing: str, stream: bytes) -> Split:
    """The bytes of `stream` by what they carry, in the framing `framing` ("sp", "zmtp",
    "zenoh")."""
    return FRAMINGS[framing](stream)
