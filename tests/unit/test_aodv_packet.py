"""AODV wire format against bytes laid out by hand from the RFC 3561 section 5 figures."""

import contextlib
import random

import pytest

from aodv.packet import (
    MalformedPacket,
    Rerr,
    Rrep,
    RrepAck,
    Rreq,
    decode,
    encode,
    is_hello,
)

# RFC 3561 5.1: Type=1 | J R G D U reserved | reserved | Hop Count, then five 32-bit words.
RREQ_BYTES = bytes(
    [1, 0b0011_1000, 0x00, 3]  # type 1, G D U set, hop count 3
    + [0x00, 0x00, 0x01, 0x02]  # RREQ ID 258
    + [10, 0, 0, 5]  # Destination IP
    + [0xFF, 0xFF, 0xFF, 0xFE]  # Destination Sequence Number
    + [10, 0, 0, 1]  # Originator IP
    + [0x00, 0x00, 0x00, 0x07]  # Originator Sequence Number
)
RREQ_MSG = Rreq(
    rreq_id=258,
    dest="10.0.0.5",
    dest_seq=0xFFFFFFFE,
    orig="10.0.0.1",
    orig_seq=7,
    hop_count=3,
    gratuitous=True,
    dest_only=True,
    unknown_seq=True,
)

# RFC 3561 5.2: Type=2 | R A reserved(9) Prefix Sz(5) | Hop Count, then four words.
RREP_BYTES = bytes(
    [2, 0b0100_0000, 0b0000_0000, 2]  # type 2, A set, prefix 0, hop count 2
    + [10, 0, 0, 5]  # Destination IP
    + [0x00, 0x00, 0x00, 0x09]  # Destination Sequence Number
    + [10, 0, 0, 1]  # Originator IP
    + [0x00, 0x00, 0x17, 0x70]  # Lifetime 6000 ms
)
RREP_MSG = Rrep(
    dest="10.0.0.5", dest_seq=9, orig="10.0.0.1", lifetime_ms=6000, hop_count=2, ack_required=True
)

# RFC 3561 5.3: Type=3 | N reserved | DestCount, then (address, seqno) pairs.
RERR_BYTES = bytes(
    [3, 0x80, 0x00, 2]  # type 3, N set, DestCount 2
    + [10, 0, 0, 4, 0x00, 0x00, 0x00, 0x0A]
    + [10, 0, 0, 5, 0x80, 0x00, 0x00, 0x00]
)
RERR_MSG = Rerr(unreachable=(("10.0.0.4", 10), ("10.0.0.5", 0x80000000)), no_delete=True)

# HELLO: a RREP about its sender, with the Hello Interval extension (type 1, length 4).
HELLO_BYTES = bytes(
    [2, 0, 0, 0]
    + [10, 0, 0, 3, 0, 0, 0, 4]
    + [10, 0, 0, 3, 0x00, 0x00, 0x07, 0xD0]  # Lifetime 2000 ms
    + [1, 4, 0x00, 0x00, 0x03, 0xE8]  # extension type 1, length 4, 1000 ms
)
HELLO_MSG = Rrep(
    dest="10.0.0.3", dest_seq=4, orig="10.0.0.3", lifetime_ms=2000, hello_interval_ms=1000
)


@pytest.mark.parametrize(
    "msg, raw",
    [
        (RREQ_MSG, RREQ_BYTES),
        (RREP_MSG, RREP_BYTES),
        (RERR_MSG, RERR_BYTES),
        (RrepAck(), bytes([4, 0])),
        (HELLO_MSG, HELLO_BYTES),
    ],
)
def test_encode_matches_rfc_figure_and_decodes_back(msg, raw):
    assert encode(msg) == raw
    assert decode(raw) == msg


def test_every_rreq_flag_bit_is_where_the_figure_puts_it():
    for name, bit in [
        ("join", 0x80),
        ("repair", 0x40),
        ("gratuitous", 0x20),
        ("dest_only", 0x10),
        ("unknown_seq", 0x08),
    ]:
        msg = Rreq(rreq_id=1, dest="10.0.0.2", dest_seq=0, orig="10.0.0.1", orig_seq=1)
        raw = encode(msg._replace(**{name: True}))
        assert raw[1] == bit, name


def test_rrep_repair_flag_and_prefix_size():
    raw = encode(Rrep("10.0.0.2", 1, "10.0.0.1", 0, repair=True, prefix_size=24))
    assert raw[1] == 0x80 and raw[2] == 24


def test_reserved_bits_are_ignored_on_receipt():
    raw = bytearray(RREQ_BYTES)
    raw[1] |= 0x07
    raw[2] = 0xFF
    assert decode(bytes(raw)) == RREQ_MSG


def test_hello_interval_wireshark_type_is_accepted():
    raw = bytearray(HELLO_BYTES)
    raw[20] = 2
    assert decode(bytes(raw)).hello_interval_ms == 1000


def test_unknown_extension_is_skipped():
    assert decode(RREQ_BYTES + bytes([7, 2, 0xAA, 0xBB])) == RREQ_MSG


def test_is_hello():
    assert is_hello(HELLO_MSG, "10.0.0.3")
    assert not is_hello(HELLO_MSG, "10.0.0.2")
    assert not is_hello(RREP_MSG, "10.0.0.5")


@pytest.mark.parametrize(
    "raw",
    [
        b"",
        bytes([0]),
        bytes([5, 0]),
        bytes([255] * 30),
        RREQ_BYTES[:-1],
        RREP_BYTES[:19],
        bytes([3, 0, 0, 0]),  # RERR with DestCount 0
        RERR_BYTES[:-1],
        bytes([3, 0, 0]),
        bytes([4]),
        RREQ_BYTES + bytes([1]),  # truncated extension header
        RREQ_BYTES + bytes([1, 4, 0]),  # extension longer than the datagram
        RREQ_BYTES + bytes([0, 0]),  # reserved extension type 0
        HELLO_BYTES[:-1],
        RREP_BYTES + bytes([1, 2, 0, 0]),  # hello interval of 2 bytes
    ],
)
def test_malformed_raises_specific_error(raw):
    with pytest.raises(MalformedPacket):
        decode(raw)


def test_random_bytes_never_raise_anything_else():
    rng = random.Random(3561)
    for _ in range(5000):
        raw = bytes(rng.randrange(256) for _ in range(rng.randrange(40)))
        with contextlib.suppress(MalformedPacket):
            decode(raw)


def test_encode_rejects_out_of_range_fields():
    with pytest.raises(ValueError):
        encode(Rreq(rreq_id=2**32, dest="10.0.0.2", dest_seq=0, orig="10.0.0.1", orig_seq=0))
    with pytest.raises(ValueError):
        encode(Rerr(unreachable=()))
