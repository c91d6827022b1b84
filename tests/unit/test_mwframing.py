"""The middleware's traffic as its own class of the capture metrics: the framings of nanomsg,
ZeroMQ and Zenoh walked (testbed.analysis.mwframing), and pcapmetrics' middleware counts on
hand-made frames. (DDS's RTPS: test_rtps.py; tests/integration/test_middleware.py checks
them on real captures.)"""

import struct

from testbed.analysis import mwframing
from testbed.analysis import pcapmetrics as pm
from testbed.analysis.pcapmetrics import Frame

SP_PUSH = b"\x00SP\x00\x00\x50\x00\x00"  # nanomsg's header of a PUSH socket
GOAL = b'{"k": "goal", "from": 1, "step": 3, "goal": [1.0, 2.0], "cost": 2.0, "n": 1}'
# A ZMTP 3.0 greeting (signature, version 3.0, mechanism NULL, as-server 0, filler).
ZMTP_GREETING = b"\xff" + b"\x00" * 8 + b"\x7f" + b"\x03\x00" + b"NULL".ljust(20, b"\x00")
ZMTP_GREETING += b"\x00" * 32
_READY_BODY = b"\x05READY\x0bSocket-Type\x00\x00\x00\x04PUSH"
READY = b"\x04" + bytes([len(_READY_BODY)]) + _READY_BODY  # a command: its flags, size, body


def sp_message(body: bytes) -> bytes:
    return struct.pack("!Q", len(body)) + body


def test_nanomsg_bytes_are_its_header_and_length_prefixes_around_the_messages():
    stream = SP_PUSH + sp_message(GOAL) + sp_message(GOAL)
    s = mwframing.split("sp", stream)
    assert (s.messages, s.payload, s.protocol, s.unparsed) == (2, 2 * len(GOAL), 8 + 16, 0)
    cut = mwframing.split("sp", stream[:-5])  # the capture ended mid-message
    assert (cut.messages, cut.unparsed) == (1, 8 + len(GOAL) - 5)
    mid = mwframing.split("sp", sp_message(GOAL))  # the connection's start was not captured
    assert (mid.messages, mid.unparsed) == (0, 8 + len(GOAL))


def test_zeromq_bytes_are_greeting_commands_and_frame_headers_around_the_messages():
    assert len(ZMTP_GREETING) == 64
    stream = ZMTP_GREETING + READY + b"\x00" + bytes([len(GOAL)]) + GOAL
    s = mwframing.split("zmtp", stream)
    assert (s.messages, s.payload, s.protocol, s.unparsed) == (1, len(GOAL), 64 + len(READY) + 2, 0)
    # REQ: an empty delimiter (MORE) before the message; REP's reply: delimiter, empty frame.
    request = b"\x01\x00" + b"\x00" + bytes([len(GOAL)]) + GOAL
    reply = b"\x01\x00\x00\x00"
    s = mwframing.split("zmtp", ZMTP_GREETING + READY + request + reply)
    assert (s.messages, s.payload, s.protocol) == (1, len(GOAL), 64 + len(READY) + 4 + 4)
    long = b"\x02" + struct.pack("!Q", 300) + b"x" * 300  # a LONG frame
    assert mwframing.split("zmtp", ZMTP_GREETING + long).payload == 300
    assert mwframing.split("zmtp", b"\x00" + bytes([3]) + b"abc").unparsed == 5


M1, M2 = "02:00:00:00:00:01", "02:00:00:00:00:02"
A1, A2 = "10.0.0.1", "10.0.0.2"


def _tcp(src_mac, src, dst, sport, dport, seq, payload=b"", length=None):
    return Frame(1.0, 66 + len(payload) if length is None else length, src_mac, M2, src, dst, 6,
                 64, tcp_sport=sport, tcp_dport=dport, tcp_seq=seq, tcp_len=len(payload),
                 tcp_payload=payload)  # fmt: skip


def test_the_captures_count_the_middleware_apart_from_tcp_and_the_messages_apart_from_it():
    msg = sp_message(GOAL)
    r1 = [
        _tcp(M1, A1, A2, 40000, pm.GOAL_PORT, 99),  # SYN
        _tcp(M1, A1, A2, 40000, pm.GOAL_PORT, 100, SP_PUSH),
        _tcp(M1, A1, A2, 40000, pm.GOAL_PORT, 108, msg),
        _tcp(M1, A1, A2, 40000, pm.GOAL_PORT, 108, msg),  # retransmitted
        _tcp(M1, A1, A2, 40000, 5555, 7, b"other tcp"),  # not the middleware's port
        _tcp(M2, A2, A1, pm.GOAL_PORT, 40000, 500),  # received: robot 2's ACK
    ]
    m = pm.compute({1: r1}, {1: A1}, 654, middleware="nanomsg")
    mw = m["robots"]["r1"]["middleware"]
    assert (mw["tx_packets"], mw["tcp_control_packets"], mw["data_packets"]) == (4, 1, 3)
    assert mw["payload_bytes"] == 8 + 2 * len(msg)
    assert mw["retransmitted_payload_bytes"] == len(msg)
    assert (mw["messages"], mw["message_bytes"]) == (1, len(GOAL))
    assert (mw["protocol_bytes"], mw["unparsed_bytes"]) == (8 + 8, 0)
    team = m["middleware"]
    assert (team["name"], team["port"], team["framing"]) == ("nanomsg", pm.GOAL_PORT, "sp")
    assert team["message_fraction_bytes"] == len(GOAL) / mw["tx_bytes"]
    # The routing metrics still count all TCP, the middleware's included.
    assert m["tcp_segments_sent"] == 3
    other = pm.compute({1: r1}, {1: A1}, 654, middleware="pigeon")  # no framing: not a class
    assert other["middleware"] == {"name": "pigeon", "port": pm.GOAL_PORT, "framing": None}
    assert "middleware" not in other["robots"]["r1"]


def test_the_goal_port_is_the_robots():
    from node.launch import NodeArgs

    assert NodeArgs(robot=1, robots=1, body="b").goal_port == pm.GOAL_PORT


def test_every_framing_counts_its_own_bytes_by_kind():
    sp = mwframing.split("sp", SP_PUSH + sp_message(GOAL) + sp_message(GOAL))
    assert sp.kinds == {"sp_header": [1, 8], "length_prefix": [2, 16]}
    request = b"\x01\x00" + b"\x00" + bytes([len(GOAL)]) + GOAL
    zmtp = mwframing.split("zmtp", ZMTP_GREETING + READY + request + b"\x01\x00\x00\x00")
    assert zmtp.kinds == {
        "greeting": [1, 64], "command": [1, len(READY)], "empty_frame": [3, 6],
        "frame_header": [1, 2],
    }  # fmt: skip
    for s in (sp, zmtp):
        assert sum(b for _, b in s.kinds.values()) == s.protocol


# Zenoh over TCP, from a captured run (zenoh 1.10): the dialling side's INIT, a keep-alive, a
# FRAME holding a PUSH whose PUT carries a goal message, and a CLOSE; each batch after its
# 2-byte little-endian length.
ZENOH_INIT = bytes.fromhex("1900c109f104ae620b942da310be6babd4a1024bcb0a88fe812701")
ZENOH_KEEP_ALIVE = bytes.fromhex("010004")
ZENOH_CLOSE = bytes.fromhex("02000300")
ZENOH_GOAL = (
    b'{"k": "goal", "from": 1, "step": 25, "goal": [0.8500000000000001, 4.75], '
    b'"cost": 1.879, "n": 2}'
)
ZENOH_PUT = bytes.fromhex("6a0025fc9ebc649d012115015f") + ZENOH_GOAL


def zenoh_batch(body: bytes) -> bytes:
    return struct.pack("<H", len(body)) + body


def test_zenoh_bytes_are_batches_around_the_messages_found_by_their_length_and_body():
    assert len(ZENOH_GOAL) == 0x5F and len(ZENOH_PUT) == 2 + 0x6A
    stream = ZENOH_INIT + ZENOH_KEEP_ALIVE + ZENOH_PUT + ZENOH_CLOSE
    s = mwframing.split("zenoh", stream)
    assert (s.messages, s.payload, s.unparsed) == (1, len(ZENOH_GOAL), 0)
    assert s.protocol == len(stream) - len(ZENOH_GOAL)
    assert s.kinds == {
        "batch_length": [4, 8], "handshake": [1, 25], "keep_alive": [1, 1],
        "message_headers": [1, 0x6A - len(ZENOH_GOAL)], "close": [1, 2],
    }  # fmt: skip
    # Two puts in one FRAME; a body of 200 bytes has a 2-byte length (c8 01).
    long = b'{"k": "replan", "pad": "' + b"x" * 174 + b'"}'
    assert len(long) == 200
    two = zenoh_batch(b"\xa5\x01\x9d\x01\x01\x5f" + ZENOH_GOAL + b"\x9d\x01\x01\xc8\x01" + long)
    s = mwframing.split("zenoh", ZENOH_INIT + two)
    assert (s.messages, s.payload) == (2, len(ZENOH_GOAL) + 200)
    assert s.kinds["message_headers"] == [2, 6 + 5]
    # Not a message: a JSON body after a length that is not its own, one without "k" first,
    # one that is not JSON; then the batch is a FRAME of the middleware's own.
    for body in (b"\x05\x01\x60" + ZENOH_GOAL, b'\x05\x01\x0a{"x": "goal"}', b'\x05\x01\x05{"k":'):
        s = mwframing.split("zenoh", ZENOH_INIT + zenoh_batch(body))
        assert (s.messages, s.kinds["frames"]) == (0, [1, len(body)])
    # A stream whose first batch is not an INIT (its start not captured), or cut short.
    assert mwframing.split("zenoh", ZENOH_PUT).unparsed == len(ZENOH_PUT)
    cut = mwframing.split("zenoh", ZENOH_INIT + ZENOH_PUT[:-1])
    assert (cut.messages, cut.unparsed) == (0, len(ZENOH_PUT) - 1)
