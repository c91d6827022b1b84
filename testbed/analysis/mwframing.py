"""The middlewares' framing on the wire: which bytes of a TCP stream are the robots' messages
and which the middleware's own (`split`), for the captures' middleware metrics
(testbed.analysis.pcapmetrics).

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

What is the middleware's own is counted in `protocol`, the robots' message bodies in
`payload`, and bytes that cannot be walked (a stream whose start was not captured, a
gap, a frame cut short at the capture's end) in `unparsed`. Pure: bytes in, counts out.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

SP_MAGIC = b"\x00SP\x00"
SP_HEADER = 8
SP_LENGTH = struct.Struct("!Q")
ZMTP_GREETING = 64
ZMTP_MORE, ZMTP_LONG, ZMTP_COMMAND = 0x01, 0x02, 0x04


@dataclass
class Split:
    messages: int = 0  # the robots' messages (a multipart ZeroMQ message is one)
    payload: int = 0  # their bytes
    protocol: int = 0  # the middleware's own bytes: headers, greetings, commands, replies
    unparsed: int = 0  # bytes that could not be walked

    def add(self, other: Split) -> None:
        self.messages += other.messages
        self.payload += other.payload
        self.protocol += other.protocol
        self.unparsed += other.unparsed


def split_sp(stream: bytes) -> Split:
    """One direction of a nanomsg (SP over TCP) connection."""
    out = Split()
    if not stream.startswith(SP_MAGIC) or len(stream) < SP_HEADER:
        out.unparsed = len(stream)
        return out
    out.protocol = SP_HEADER
    at = SP_HEADER
    while at + SP_LENGTH.size <= len(stream):
        (size,) = SP_LENGTH.unpack_from(stream, at)
        if size > len(stream) - at - SP_LENGTH.size:
            break
        out.protocol += SP_LENGTH.size
        out.payload += size
        out.messages += 1
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
    out.protocol = ZMTP_GREETING
    at = ZMTP_GREETING
    while at + 2 <= len(stream):
        flags = stream[at]
        head = 9 if flags & ZMTP_LONG else 2
        if at + head > len(stream):
            break
        size = int.from_bytes(stream[at + 1 : at + head], "big")
        if size > len(stream) - at - head:
            break
        if flags & ZMTP_COMMAND or size == 0:
            out.protocol += head + size
        else:
            out.protocol += head
            out.payload += size
            if not flags & ZMTP_MORE:
                out.messages += 1
        at += head + size
    out.unparsed = len(stream) - at
    return out


FRAMINGS = {"sp": split_sp, "zmtp": split_zmtp}


def split(framing: str, stream: bytes) -> Split:
    """The bytes of `stream` by what they carry, in the framing `framing` ("sp", "zmtp")."""
    return FRAMINGS[framing](stream)
