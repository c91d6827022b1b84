"""The middleware's traffic as its own class of the capture metrics: the framings of nanomsg
and ZeroMQ walked (testbed.analysis.mwframing), and pcapmetrics' middleware counts on
hand-made frames. (tests/integration/test_middleware.py checks them on a real capture.)"""

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
    other = pm.compute(
        {1: r1}, {1: A1}, 654, middleware="dds"
    )  # no framing known here: not a class
    assert other["middleware"] == {"name": "dds", "port": pm.GOAL_PORT, "framing": None}
    assert "middleware" not in other["robots"]["r1"]


def test_the_goal_port_is_the_robots():
    from node.launch import NodeArgs

    assert NodeArgs(robot=1, robots=1, body="b").goal_port == pm.GOAL_PORT
