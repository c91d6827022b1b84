"""DDS's traffic in the captures: RTPS datagrams walked into the robots' messages and Cyclone
DDS's own kinds (testbed.analysis.rtps), on a datagram from a real run and on hand-made
ones, and pcapmetrics' middleware counts for a DDS run on hand-made frames.
(tests/integration/test_middleware.py checks them on real captures, against tshark's own
RTPS dissector.)"""

import struct

from testbed.analysis import pcapmetrics as pm
from testbed.analysis import rtps
from testbed.analysis.pcapmetrics import Frame

# One datagram of a captured 2-robot DDS run (Cyclone DDS 11.0.1): robot 1's user writer
# (entity 0x00000303) sends its goal to robot 2's reader: INFO_TS, DATA, HEARTBEAT.
REAL_GOAL = bytes.fromhex(
    "52545053020501100110fa9595b49646f4f2f6ce090108004b0a086b42bbb65f1505840000001000000000"
    "000000030300000000010000000001000002000000010000005f0000007b226b223a2022676f616c222c20"
    "2266726f6d223a20312c202273746570223a2032352c2022676f616c223a205b302e3835303030303030"
    "30303030303030312c20342e37355d2c2022636f7374223a20312e3837392c20226e223a20327d000701"
    "1c0000000000000003030000000001000000000000000100000003000000"
)
GOAL = (
    b'{"k": "goal", "from": 1, "step": 25, "goal": [0.8500000000000001, 4.75], '
    b'"cost": 1.879, "n": 2}'
)
PREFIX = bytes(range(1, 13))
USER_WRITER, USER_READER = bytes.fromhex("00000303"), bytes.fromhex("00000204")
SPDP_WRITER, SEDP_PUB_WRITER = bytes.fromhex("000100c2"), bytes.fromhex("000003c2")
LIVELINESS_READER, UNKNOWN = bytes.fromhex("000200c7"), bytes(4)


def datagram(*subs: bytes, prefix: bytes = PREFIX) -> bytes:
    return b"RTPS\x02\x05\x01\x10" + prefix + b"".join(subs)


def sub(sub_id: int, flags: int, body: bytes, little: bool = True) -> bytes:
    return bytes([sub_id, flags | little]) + struct.pack("<H" if little else ">H", len(body)) + body


def info_ts() -> bytes:
    return sub(rtps.INFO_TS, 0, b"\x00" * 8)


def info_dst() -> bytes:
    return sub(rtps.INFO_DST, 0, bytes(12))


def goal_sample(msg: bytes, encapsulation: int = 0x0001, little: bool = True) -> bytes:
    e = "<" if little else ">"
    dheader = struct.pack(e + "I", 12 + len(msg)) if encapsulation in (0x0014, 0x0015) else b""
    data = dheader + struct.pack(e + "iiI", 2, 1, len(msg)) + msg
    return struct.pack(">HH", encapsulation, 0) + data + b"\x00" * (-len(data) % 4)


def data(writer: bytes, sn: int, payload: bytes, *, qos: bytes = b"", little=True, flags=0x04):
    e = "<" if little else ">"
    body = struct.pack(e + "HH", 0, 16) + UNKNOWN + writer + struct.pack(e + "iI", 0, sn)
    return sub(rtps.DATA, flags | (0x02 if qos else 0), body + qos + payload, little)


def heartbeat(writer: bytes, reader: bytes = UNKNOWN) -> bytes:
    return sub(rtps.HEARTBEAT, 0, reader + writer + struct.pack("<iIiIi", 0, 1, 0, 1, 1))


def acknack(reader: bytes, writer: bytes) -> bytes:
    return sub(rtps.ACKNACK, 0, reader + writer + struct.pack("<iIIi", 0, 2, 0, 1))


def test_a_real_goal_datagram_is_its_message_and_cyclones_headers_around_it():
    assert len(REAL_GOAL) == 200 and GOAL in REAL_GOAL
    s = rtps.split(REAL_GOAL, set())
    assert (s.messages, s.payload, s.unparsed, s.retransmitted) == (1, len(GOAL), 0, 0)
    # 20 header, INFO_TS 12, DATA 136 (its 95 message bytes apart), HEARTBEAT 32
    assert s.kinds == {
        "rtps_header": [1, 20], "info": [1, 12], "data_headers": [1, 136 - len(GOAL)],
        "reliability": [1, 32],
    }  # fmt: skip
    assert s.protocol + s.payload == len(REAL_GOAL)


def test_each_submessage_is_counted_by_the_endpoint_it_belongs_to():
    spdp = data(SPDP_WRITER, 1, b"\x00\x03\x00\x00" + b"p" * 40)
    sedp = data(SEDP_PUB_WRITER, 1, b"\x00\x03\x00\x00" + b"s" * 60)
    d = datagram(info_dst(), info_ts(), spdp, sedp, heartbeat(SEDP_PUB_WRITER),
                 acknack(LIVELINESS_READER, UNKNOWN), acknack(USER_READER, UNKNOWN),
                 heartbeat(USER_WRITER), sub(0x80, 0, b"v" * 8))  # fmt: skip
    s = rtps.split(d, set())
    assert s.messages == 0 and s.unparsed == 0
    assert s.kinds == {
        "rtps_header": [1, 20], "info": [2, 16 + 12], "spdp": [1, len(spdp)],
        "sedp": [2, len(sedp) + 32], "liveliness": [1, 28], "reliability": [2, 28 + 32],
        "other": [1, 12],
    }  # fmt: skip
    assert s.protocol == len(d)


def test_a_goal_sample_is_read_in_every_encoding_and_with_inline_qos():
    # (big-endian, as its submessage: a status info parameter, then the sentinel)
    qos = struct.pack(">HH", 0x0071, 4) + b"\x00\x00\x00\x01" + struct.pack(">HH", 1, 0)
    for payload, little, inline in [
        (goal_sample(GOAL, 0x0000, little=False), False, b""),  # CDR big-endian
        (goal_sample(GOAL, 0x0011), True, b""),  # XCDR2
        (goal_sample(GOAL, 0x0015), True, b""),  # XCDR2 appendable: a DHEADER first
        (goal_sample(GOAL, 0x0014, little=False), False, qos),  # ... big-endian, inline QoS
    ]:
        d = datagram(data(USER_WRITER, 7, payload, qos=inline, little=little))
        s = rtps.split(d, set())
        assert (s.messages, s.payload, s.unparsed) == (1, len(GOAL), 0), payload[:2]
        assert s.kinds["data_headers"] == [1, len(d) - 20 - len(GOAL)]


def test_a_data_sent_again_by_dds_is_a_retransmission_not_another_message():
    d = datagram(info_ts(), data(USER_WRITER, 1, goal_sample(GOAL)), heartbeat(USER_WRITER))
    seen: set = set()
    first, again = rtps.split(d, seen), rtps.split(d, seen)
    assert (first.messages, again.messages) == (1, 0)
    assert again.retransmitted == len(data(USER_WRITER, 1, goal_sample(GOAL)))
    assert again.protocol == first.protocol - first.kinds["data_headers"][1]
    # The same writer's next sample, and another participant's first, are new messages.
    assert rtps.split(datagram(data(USER_WRITER, 2, goal_sample(GOAL))), seen).messages == 1
    other = datagram(data(USER_WRITER, 1, goal_sample(GOAL)), prefix=bytes(12))
    assert rtps.split(other, seen).messages == 1


def test_what_cannot_be_walked_is_unparsed():
    assert rtps.split(b"not rtps at all, a map flood", set()).unparsed == 28
    d = datagram(info_ts(), data(USER_WRITER, 1, goal_sample(GOAL)))
    cut = rtps.split(d[:-10], set())  # a length past the datagram's end
    assert (cut.messages, cut.unparsed) == (0, len(d) - 10 - 20 - 12)
    frag = sub(rtps.DATA_FRAG, 0, bytes(4) + USER_WRITER + bytes(40))  # a sample in pieces
    not_goal = data(USER_WRITER, 3, b"\x00\x01\x00\x00" + struct.pack("<iiI", 2, 1, 999))
    s = rtps.split(datagram(frag, not_goal), set())
    assert (s.messages, s.unparsed) == (0, len(frag) + len(not_goal))
    gone = data(USER_WRITER, 4, b"\x00\x01\x00\x00key!", flags=0x08)  # unregister: no data
    assert rtps.split(datagram(gone), set()).kinds["data_without_sample"] == [1, len(gone)]


def test_the_last_submessage_may_run_to_the_datagrams_end():
    last = bytearray(data(USER_WRITER, 1, goal_sample(GOAL)))
    last[2:4] = b"\x00\x00"  # octetsToNextHeader 0: to the end
    s = rtps.split(datagram(info_ts(), bytes(last)), set())
    assert (s.messages, s.payload, s.unparsed) == (1, len(GOAL), 0)


M1, M2 = "02:00:00:00:00:01", "02:00:00:00:00:02"
A1, A2 = "10.0.0.1", "10.0.0.2"
META, USER = pm.DDS_PORTS


def _udp(src_mac, src, dst, dport, payload, sport=40001, proto=17):
    return Frame(1.0, 42 + len(payload), src_mac, M2, src, dst, proto, 64, sport, dport,
                 8 + len(payload), udp_payload=payload)  # fmt: skip


def test_a_dds_runs_captures_count_cyclones_traffic_apart_from_the_messages():
    assert pm.DDS_PORTS == (5111, 5112)
    goal = datagram(info_ts(), data(USER_WRITER, 1, goal_sample(GOAL)), heartbeat(USER_WRITER))
    spdp = datagram(info_dst(), data(SPDP_WRITER, 1, b"\x00\x03\x00\x00" + b"p" * 200))
    r1 = [
        _udp(M1, A1, A2, META, spdp),
        _udp(M1, A1, A2, USER, goal),
        _udp(M1, A1, A2, USER, goal),  # resent by DDS: no second message
        _udp(M1, A1, "255.255.255.255", 5100, b"RMF2 a map flood"),  # not DDS's port
        _udp(M1, A1, A2, META, spdp, proto=1),  # an ICMP error quoting a datagram
        _udp(M2, A2, A1, USER, goal),  # received
    ]
    m = pm.compute({1: r1}, {1: A1}, 654, middleware="dds")
    mw = m["robots"]["r1"]["middleware"]
    assert (mw["tx_packets"], mw["tcp_control_packets"], mw["data_packets"]) == (3, 0, 3)
    assert mw["tx_bytes"] == 3 * 42 + len(spdp) + 2 * len(goal)
    assert mw["payload_bytes"] == len(spdp) + 2 * len(goal)
    assert (mw["messages"], mw["message_bytes"]) == (1, len(GOAL))
    resent = len(data(USER_WRITER, 1, goal_sample(GOAL)))
    assert mw["retransmitted_payload_bytes"] == resent
    assert mw["protocol_bytes"] == mw["payload_bytes"] - len(GOAL) - resent
    assert mw["unparsed_bytes"] == 0 and mw["own_bytes"] == mw["tx_bytes"] - len(GOAL)
    kinds = mw["protocol_by_kind"]
    assert kinds["spdp"]["count"] == 1 and kinds["rtps_header"]["count"] == 3
    assert kinds["reliability"] == {"count": 2, "bytes": 64}
    team = m["middleware"]
    assert (team["framing"], team["transport"], team["ports"]) == ("rtps", "udp", [5111, 5112])
    assert (
        team["message_fraction_bytes"]
        == mw["message_fraction_bytes"]
        == len(GOAL) / (mw["tx_bytes"])
    )
    assert team["protocol_by_kind"] == kinds


def test_the_middleware_class_has_one_shape_for_every_middleware():
    shapes = set()
    for name in pm.MIDDLEWARE_FRAMING:
        m = pm.compute({1: [_udp(M1, A1, A2, META, b"")]}, {1: A1}, 654, middleware=name)
        shapes.add((tuple(sorted(m["middleware"])), tuple(sorted(m["robots"]["r1"]["middleware"]))))
    assert len(shapes) == 1 and set(pm.MIDDLEWARE_FRAMING) >= {"zenoh", "dds"}


def test_udps_payload_is_read_from_tshark_only_when_asked():
    assert "udp.payload" not in pm._tshark_argv("x.pcap")
    assert pm._tshark_argv("x.pcap", udp_payload=True)[-2:] == ["-e", "udp.payload"]
    fields = ["1.5", "60", M1, M2, A1, A2, "17", "64", "40001", "5112", "26"]
    fields += [""] * (len(pm._FIELDS) - len(fields))
    (without,) = pm.parse_fields("\t".join(fields))
    (with_it,) = pm.parse_fields("\t".join([*fields, "52545053"]))
    assert (without.udp_payload, with_it.udp_payload) == (b"", b"RTPS")
