"""topology.kernel.routequery's pure halves: the RTM_GETROUTE request and the reading of the answer
(the round trip against a real kernel: tests/integration/test_medium.py)."""

import socket
import struct

from topology.kernel.routequery import RTM_GETROUTE, RTM_NEWROUTE, Route, parse, request

HDR = struct.Struct("=LHHLL")


def answer(*attrs: tuple[int, bytes], msg_type: int = RTM_NEWROUTE) -> bytes:
    body = struct.pack("=BBBBBBBBI", socket.AF_INET, 32, 0, 0, 254, 0, 0, 1, 0)
    for atype, value in attrs:
        a = struct.pack("=HH", 4 + len(value), atype) + value
        body += a + b"\0" * (-len(a) % 4)
    return HDR.pack(HDR.size + len(body), msg_type, 0, 1, 0) + body


def test_request_is_a_getroute_for_the_host():
    data = request("10.0.0.3", seq=7)
    length, msg_type, flags, seq, _ = HDR.unpack_from(data)
    assert (length, msg_type, flags, seq) == (len(data), RTM_GETROUTE, 1, 7)
    family, dst_len = data[16], data[17]
    assert (family, dst_len) == (socket.AF_INET, 32)
    assert data[-8:] == struct.pack("=HH", 8, 1) + socket.inet_aton("10.0.0.3")  # RTA_DST


def test_answer_with_gateway_and_interface():
    data = answer((1, socket.inet_aton("10.0.0.3")), (4, struct.pack("=I", 10)),
                  (5, socket.inet_aton("10.0.0.2")), (7, b"\x01"))  # fmt: skip
    assert parse(data) == Route(oif=10, gateway="10.0.0.2")


def test_answer_on_link_has_no_gateway():
    assert parse(answer((4, struct.pack("=I", 10)))) == Route(oif=10, gateway=None)


def test_an_error_or_a_short_answer_is_no_route():
    err = HDR.pack(36, 2, 0, 1, 0) + struct.pack("=i", -101) + b"\0" * 16  # NLMSG_ERROR
    assert parse(err) is None
    assert parse(b"") is None and parse(answer()[:20]) is None


def test_a_truncated_attribute_is_not_read_past():
    data = answer((4, struct.pack("=I", 10)))
    assert parse(data + struct.pack("=HH", 2, 5)) == Route(oif=10, gateway=None)
