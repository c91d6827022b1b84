"""AODV wire format (RFC 3561 section 5) on UDP port 654.

Theory of operation: every control message is an immutable NamedTuple (a frozen dataclass
cost three times as much to build, and every hop builds two or three); `encode()` lays it out
in network byte order exactly as the RFC figures do, `decode()` parses one UDP payload and
raises `MalformedPacket` (a `ValueError`) on anything that does not fit a figure: unknown
type, wrong length, a RERR with DestCount 0, a truncated or overlong extension. Nothing
here knows about sockets or time.

Layouts (bytes; flags are the high bits of the byte after Type):

    RREQ  (type 1, 24 bytes): Type | J R G D U + 11 reserved bits | Hop Count
                              RREQ ID | Dest IP | Dest Seq | Orig IP | Orig Seq
    RREP  (type 2, 20 bytes): Type | R A + 9 reserved bits | Prefix Sz (5 bits) | Hop Count
                              Dest IP | Dest Seq | Orig IP | Lifetime (ms)
    RERR  (type 3, 4 + 8 N):  Type | N + 15 reserved bits | DestCount
                              then N x (Unreachable Dest IP | Unreachable Dest Seq)
    RREP-ACK (type 4, 2 bytes): Type | Reserved

Extensions (RFC 3561 section 9): Type (1 byte) | Length (1 byte) | Length bytes of data,
appended after a message. Decision (HELLO extension type): the Hello Interval extension is
sent as type 1, which is what RFC 3561 section 9.1 and the IANA AODV registry assign.
Wireshark's dissector still uses the type of earlier drafts (2, "AODV_EXT_INT") and shows
our type 1 as a generic extension; on receipt we accept both 1 and 2. Unknown extension
types below 128 are skipped; section 9: "Extensions with types between 128 and 255 may NOT
be skipped", so a message carrying one (we know none) is malformed. Reserved bits are sent
as 0 and ignored on receipt.

A HELLO is a RREP (RFC 3561 section 6.9) with Destination = Originator = the sender,
Hop Count 0, sent to 255.255.255.255 with IP TTL 1; `is_hello()` recognises it.
"""

from __future__ import annotations

import socket
import struct
from typing import NamedTuple

AODV_PORT = 654

RREQ_TYPE = 1
RREP_TYPE = 2
RERR_TYPE = 3
RREP_ACK_TYPE = 4

# RFC 3561 section 9.1 / IANA: Hello Interval extension is type 1. Wireshark uses 2.
EXT_HELLO_INTERVAL = 1
EXT_HELLO_INTERVAL_WIRESHARK = 2
KNOWN_EXTENSIONS = frozenset({EXT_HELLO_INTERVAL, EXT_HELLO_INTERVAL_WIRESHARK})

_RREQ = struct.Struct("!BBBBI4sI4sI")
_RREP = struct.Struct("!BBBB4sI4sI")
_RERR_HEAD = struct.Struct("!BBBB")
_RERR_DEST = struct.Struct("!4sI")
_U32 = struct.Struct("!I")
_RREQ_SIZE, _RREP_SIZE = _RREQ.size, _RREP.size

# RREQ flag bits in the second byte (RFC 3561 section 5.1 figure).
_RREQ_J, _RREQ_R, _RREQ_G, _RREQ_D, _RREQ_U = 0x80, 0x40, 0x20, 0x10, 0x08
# RREP flag bits in the second byte (section 5.2 figure); prefix size is the low 5 bits
# of the third byte.
_RREP_R, _RREP_A = 0x80, 0x40
# RERR flag bit (section 5.3 figure).
_RERR_N = 0x80

MAX_U32 = 0xFFFFFFFF


# decode() builds a message from the flag byte through these tables (one lookup instead of
# five masks and bools) and with tuple.__new__ (positional, no keyword parsing): a decode
# runs on every hop of every discovery, right after a wake-up, when Python is slowest.
_RREQ_FLAGS = tuple(
    (bool(f & _RREQ_J), bool(f & _RREQ_R), bool(f & _RREQ_G), bool(f & _RREQ_D), bool(f & _RREQ_U))
    for f in range(256)
)
_RREP_FLAGS = tuple((bool(f & _RREP_R), bool(f & _RREP_A)) for f in range(256))
_new = tuple.__new__


class MalformedPacket(ValueError):
    """A datagram on port 654 that is not a well-formed RFC 3561 message."""


_addr = socket.inet_ntoa


def _raw(addr: str) -> bytes:
    try:
        return socket.inet_pton(socket.AF_INET, addr)
    except OSError:
        raise ValueError(f"not an IPv4 address: {addr!r}") from None


def _check_u32(name: str, value: int) -> None:
    if not 0 <= value <= MAX_U32:
        raise ValueError(f"{name}={value} does not fit in 32 bits")


class Rreq(NamedTuple):
    """Route Request (RFC 3561 section 5.1)."""

    rreq_id: int
    dest: str
    dest_seq: int
    orig: str
    orig_seq: int
    hop_count: int = 0
    join: bool = False
    repair: bool = False
    gratuitous: bool = False
    dest_only: bool = False
    unknown_seq: bool = False

    @property  # not a class attribute: NamedTuple would make it a field for mypy
    def type_name(self) -> str:
        return "RREQ"

    def encode(self) -> bytes:
        flags = (
            (_RREQ_J if self.join else 0)
            | (_RREQ_R if self.repair else 0)
            | (_RREQ_G if self.gratuitous else 0)
            | (_RREQ_D if self.dest_only else 0)
            | (_RREQ_U if self.unknown_seq else 0)
        )
        try:  # struct checks every field's range (one pack: this runs on every hop)
            return _RREQ.pack(
                RREQ_TYPE,
                flags,
                0,
                self.hop_count,
                self.rreq_id,
                _raw(self.dest),
                self.dest_seq,
                _raw(self.orig),
                self.orig_seq,
            )
        except struct.error as e:
            raise ValueError(f"{self}: a field does not fit ({e})") from None


class Rrep(NamedTuple):
    """Route Reply (RFC 3561 section 5.2); a HELLO when `hello_interval_ms` is set."""

    dest: str
    dest_seq: int
    orig: str
    lifetime_ms: int
    hop_count: int = 0
    repair: bool = False
    ack_required: bool = False
    prefix_size: int = 0
    hello_interval_ms: int | None = None

    @property  # not a class attribute: NamedTuple would make it a field for mypy
    def type_name(self) -> str:
        return "RREP"

    def encode(self) -> bytes:
        if not 0 <= self.prefix_size <= 31:
            raise ValueError(f"prefix_size={self.prefix_size} does not fit in 5 bits")
        flags = (_RREP_R if self.repair else 0) | (_RREP_A if self.ack_required else 0)
        try:  # struct checks every other field's range
            out = _RREP.pack(
                RREP_TYPE,
                flags,
                self.prefix_size,
                self.hop_count,
                _raw(self.dest),
                self.dest_seq,
                _raw(self.orig),
                self.lifetime_ms,
            )
            if self.hello_interval_ms is not None:
                out += bytes((EXT_HELLO_INTERVAL, 4)) + _U32.pack(self.hello_interval_ms)
        except struct.error as e:
            raise ValueError(f"{self}: a field does not fit ({e})") from None
        return out


class Rerr(NamedTuple):
    """Route Error (RFC 3561 section 5.3): (address, sequence number) pairs."""

    unreachable: tuple[tuple[str, int], ...]
    no_delete: bool = False

    @property  # not a class attribute: NamedTuple would make it a field for mypy
    def type_name(self) -> str:
        return "RERR"

    def encode(self) -> bytes:
        if not 1 <= len(self.unreachable) <= 0xFF:
            raise ValueError(f"a RERR carries 1..255 destinations, not {len(self.unreachable)}")
        out = [
            _RERR_HEAD.pack(RERR_TYPE, _RERR_N if self.no_delete else 0, 0, len(self.unreachable))
        ]
        for addr, seq in self.unreachable:
            _check_u32("seq", seq)
            out.append(_RERR_DEST.pack(_raw(addr), seq))
        return b"".join(out)


class RrepAck(NamedTuple):
    """Route Reply Acknowledgment (RFC 3561 section 5.4)."""

    @property  # not a class attribute: NamedTuple would make it a field for mypy
    def type_name(self) -> str:
        return "RREP-ACK"

    def encode(self) -> bytes:
        return bytes((RREP_ACK_TYPE, 0))


Message = Rreq | Rrep | Rerr | RrepAck


def encode(msg: Message) -> bytes:
    """Bytes of one control message, ready for a UDP payload."""
    return msg.encode()


def _extensions(data: bytes) -> dict[int, bytes]:
    """Parse Type-Length-Data extensions (RFC 3561 section 9) filling `data` exactly."""
    exts: dict[int, bytes] = {}
    i = 0
    while i < len(data):
        if len(data) - i < 2:
            raise MalformedPacket("truncated extension header")
        etype, elen = data[i], data[i + 1]
        if etype == 0:
            raise MalformedPacket("extension type 0 is reserved")
        if etype >= 128 and etype not in KNOWN_EXTENSIONS:
            # RFC 3561 9: "Extensions with types between 128 and 255 may NOT be skipped."
            raise MalformedPacket(
                f"extension type {etype} (>= 128) is unknown and may not be skipped"
            )
        body = data[i + 2 : i + 2 + elen]
        if len(body) != elen:
            raise MalformedPacket(f"extension type {etype} claims {elen} bytes, {len(body)} left")
        exts.setdefault(etype, body)
        i += 2 + elen
    return exts


def _hello_interval(exts: dict[int, bytes]) -> int | None:
    for etype in (EXT_HELLO_INTERVAL, EXT_HELLO_INTERVAL_WIRESHARK):
        body = exts.get(etype)
        if body is not None:
            if len(body) != 4:
                raise MalformedPacket(f"hello interval extension of {len(body)} bytes")
            return _U32.unpack(body)[0]
    return None


def decode(data: bytes) -> Message:
    """Parse one UDP payload; raise MalformedPacket if it is not an RFC 3561 message."""
    if not data:
        raise MalformedPacket("empty datagram")
    mtype = data[0]
    n = len(data)
    if mtype == RREQ_TYPE:
        if n < _RREQ_SIZE:
            raise MalformedPacket(f"RREQ of {n} bytes, needs {_RREQ_SIZE}")
        _, flags, _, hops, rid, dest, dseq, orig, oseq = _RREQ.unpack_from(data)
        if n > _RREQ_SIZE:
            _extensions(data[_RREQ_SIZE:])
        # Field order of Rreq: rreq_id, dest, dest_seq, orig, orig_seq, hop_count, flags.
        return _new(Rreq, (rid, _addr(dest), dseq, _addr(orig), oseq, hops, *_RREQ_FLAGS[flags]))
    if mtype == RREP_TYPE:
        if n < _RREP_SIZE:
            raise MalformedPacket(f"RREP of {n} bytes, needs {_RREP_SIZE}")
        _, flags, prefix, hops, dest, dseq, orig, lifetime = _RREP.unpack_from(data)
        hello = _hello_interval(_extensions(data[_RREP_SIZE:])) if n > _RREP_SIZE else None
        # Field order of Rrep: dest, dest_seq, orig, lifetime_ms, hop_count, repair,
        # ack_required, prefix_size, hello_interval_ms.
        return _new(
            Rrep,
            (
                _addr(dest),
                dseq,
                _addr(orig),
                lifetime,
                hops,
                *_RREP_FLAGS[flags],
                prefix & 0x1F,
                hello,
            ),
        )
    if mtype == RERR_TYPE:
        if len(data) < _RERR_HEAD.size:
            raise MalformedPacket(f"RERR of {len(data)} bytes")
        _, flags, _, count = _RERR_HEAD.unpack_from(data)
        if count == 0:
            raise MalformedPacket("RERR with DestCount 0")
        end = _RERR_HEAD.size + count * _RERR_DEST.size
        if len(data) < end:
            raise MalformedPacket(f"RERR with DestCount {count} in {len(data)} bytes")
        dests = tuple(
            (_addr(a), s)
            for a, s in (
                _RERR_DEST.unpack_from(data, _RERR_HEAD.size + k * _RERR_DEST.size)
                for k in range(count)
            )
        )
        _extensions(data[end:])
        return Rerr(unreachable=dests, no_delete=bool(flags & _RERR_N))
    if mtype == RREP_ACK_TYPE:
        if len(data) < 2:
            raise MalformedPacket("RREP-ACK of 1 byte")
        _extensions(data[2:])
        return RrepAck()
    raise MalformedPacket(f"unknown AODV message type {mtype}")


def is_hello(msg: Message, src: str) -> bool:
    """True for a HELLO (RFC 3561 section 6.9): a RREP about its own sender, 0 hops.

    Decision: the RFC fixes only Destination (the sender) and Hop Count (0) of a HELLO; we
    also require Originator = Destination = IP source, which no route-carrying RREP has
    (a RREP's Originator is the node that asked, never the one that answers).
    """
    return isinstance(msg, Rrep) and msg.hop_count == 0 and msg.dest == msg.orig == src
