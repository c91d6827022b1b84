"""topology.kernel.netlinkmsg against bytes checked by hand, field by field, against
linux/netlink.h and linux/rtnetlink.h (on a little-endian host, as netlink is in host order):
what `ip route replace`, `ip route del` and `ip route get` would send, and the reading of
answers the kernel sends."""

import socket
import struct
import sys

import pytest

from topology.kernel import netlinkmsg as nl

pytestmark = pytest.mark.skipif(sys.byteorder != "little", reason="golden bytes are little-endian")

# ip route replace 10.0.0.5/32 via 10.0.0.2 dev <ifindex 10> onlink proto 101, seq 1, no ack
REPLACE_VIA = bytes.fromhex(
    "34000000"  # nlmsg_len 52 = 16 header + 12 rtmsg + 3 attributes of 8
    "1800"  # nlmsg_type RTM_NEWROUTE (24)
    "0105"  # nlmsg_flags NLM_F_REQUEST 0x1 | NLM_F_REPLACE 0x100 | NLM_F_CREATE 0x400
    "01000000"  # nlmsg_seq 1
    "00000000"  # nlmsg_pid 0: to the kernel
    "02"  # rtm_family AF_INET
    "20"  # rtm_dst_len 32
    "00" "00"  # rtm_src_len, rtm_tos
    "fe"  # rtm_table RT_TABLE_MAIN (254)
    "65"  # rtm_protocol 101
    "00"  # rtm_scope RT_SCOPE_UNIVERSE: through a gateway
    "01"  # rtm_type RTN_UNICAST
    "04000000"  # rtm_flags RTNH_F_ONLINK
    "0800" "0100" "0a000005"  # RTA_DST 10.0.0.5
    "0800" "0400" "0a000000"  # RTA_OIF 10
    "0800" "0500" "0a000002"  # RTA_GATEWAY 10.0.0.2
)  # fmt: skip

# ip route replace 10.0.0.2/32 dev <ifindex 10> scope link proto 102, seq 0, acknowledged
REPLACE_DIRECT = bytes.fromhex(
    "2c000000" "1800"
    "0505"  # NLM_F_REQUEST | NLM_F_ACK 0x4 | NLM_F_REPLACE | NLM_F_CREATE
    "00000000" "00000000"
    "02" "20" "00" "00" "fe" "66"
    "fd"  # RT_SCOPE_LINK (253): the next hop is the destination
    "01" "00000000"  # unicast, no flags: no gateway, so no onlink
    "0800" "0100" "0a000002"  # RTA_DST
    "0800" "0400" "0a000000"  # RTA_OIF
)  # fmt: skip

# ip route del 10.0.0.5/32 proto 101, seq 4, acknowledged
DELETE = bytes.fromhex(
    "24000000"  # 36 = 16 + 12 + 8
    "1900"  # RTM_DELROUTE (25)
    "0500"  # NLM_F_REQUEST | NLM_F_ACK
    "04000000" "00000000"
    "02" "20" "00" "00" "fe" "65"
    "ff"  # RT_SCOPE_NOWHERE: any scope
    "00"  # RTN_UNSPEC: any type
    "00000000"
    "0800" "0100" "0a000005"  # RTA_DST
)  # fmt: skip

# ip route get 10.0.0.3, seq 7
GET = bytes.fromhex(
    "24000000"
    "1a00"  # RTM_GETROUTE (26)
    "0100"  # NLM_F_REQUEST
    "07000000" "00000000"
    "02" "20" "00" "00"
    "00" "00" "00" "00"  # table, protocol, scope, type unspecified
    "00000000"
    "0800" "0100" "0a000003"  # RTA_DST
)  # fmt: skip


def test_route_replace_via_a_gateway():
    assert nl.route_replace("10.0.0.5", "10.0.0.2", 10, 101, ack=False, seq=1) == REPLACE_VIA


def test_route_replace_to_a_neighbour():
    assert nl.route_replace("10.0.0.2", "10.0.0.2", 10, 102, ack=True) == REPLACE_DIRECT


def test_route_delete():
    assert nl.route_delete("10.0.0.5", 101, ack=True, seq=4) == DELETE


def test_route_get():
    assert nl.route_get("10.0.0.3", seq=7) == GET


def test_a_batch_numbers_its_own_requests():
    buf = bytearray(REPLACE_DIRECT)
    nl.set_seq(buf, 9)
    assert (
        buf[8:12] == b"\x09\0\0\0"
        and buf[:8] + buf[12:] == REPLACE_DIRECT[:8] + REPLACE_DIRECT[12:]
    )


def test_attributes_are_padded_but_their_length_is_not():
    assert nl.string_attr(1, "aodv") == bytes.fromhex("09000100616f647600000000")
    assert [(k, v) for k, v in nl.attr_values(nl.string_attr(1, "aodv") + nl.u32_attr(2, 5))] == [
        (1, b"aodv\0"),
        (2, b"\x05\0\0\0"),
    ]


def _answer(seq: int, *attrs: bytes, proto: int = 101) -> bytes:
    body = bytes([socket.AF_INET, 32, 0, 0, 254, proto, 0, 1]) + b"\0" * 4 + b"".join(attrs)
    return struct.pack("=LHHLL", 16 + len(body), 24, 2, seq, 0) + body


def test_a_datagram_of_answers_is_read_message_by_message():
    a = _answer(3, nl.attr(1, socket.inet_aton("10.0.0.9")), nl.u32_attr(4, 10))
    b = _answer(4, nl.attr(5, socket.inet_aton("10.0.0.2")), proto=102)
    err = struct.pack("=LHHLLi", 36, 2, 0, 5, 0, -3) + b"\0" * 16  # ESRCH
    data = a + b + err
    found = list(nl.messages(data))
    assert [(t, s) for t, s, _, _ in found] == [(24, 3), (24, 4), (2, 5)]
    assert nl.parse_route(data, *found[0][2:]) == nl.RouteAnswer(32, 101, "10.0.0.9", 10, None)
    assert nl.parse_route(data, *found[1][2:]) == nl.RouteAnswer(32, 102, None, None, "10.0.0.2")
    assert nl.error_code(data, found[2][2]) == 3


def test_malformed_answers_are_not_read_past():
    good = _answer(1, nl.u32_attr(4, 10))
    # An attribute claiming more than the message holds, one claiming less than its header.
    assert nl.parse_route(good + b"\x08\0\x01\0\x0a", 16, len(good) + 5).dst is None
    assert nl.parse_route(good + b"\x02\0\x05\0", 16, len(good) + 4).gateway is None
    assert nl.parse_route(good, 16, 20) is None  # no room for an rtmsg
    assert list(nl.messages(struct.pack("=LHHLL", 8, 24, 0, 1, 0))) == []  # length < header


def test_set_elements_dump_and_answer():
    req = nl.set_elements_dump("aodv", "used", 1)
    assert req == bytes.fromhex(
        "2c000000"  # 44 = 16 + 4 nfgenmsg + 12 + 12
        "0d0a"  # NFNL_SUBSYS_NFTABLES << 8 | NFT_MSG_GETSETELEM
        "0103"  # NLM_F_REQUEST | NLM_F_DUMP
        "01000000" "00000000"
        "02" "00" "0000"  # nfgenmsg: AF_INET, version 0, resource 0
        "0900" "0100" "616f647600" "000000"  # NFTA_SET_ELEM_LIST_TABLE "aodv"
        "0900" "0200" "7573656400" "000000"  # NFTA_SET_ELEM_LIST_SET "used"
    )  # fmt: skip

    def elem(addr: str) -> bytes:  # NFTA_LIST_ELEM { NFTA_SET_ELEM_KEY { NFTA_DATA_VALUE } }
        key = nl.attr(1 | nl.NLA_F_NESTED, nl.attr(1, socket.inet_aton(addr)))
        return nl.attr(1 | nl.NLA_F_NESTED, key)

    elements = nl.attr(3 | nl.NLA_F_NESTED, elem("10.0.0.4") + elem("10.0.0.7"))
    payload = nl.NFGENMSG.pack(socket.AF_INET, 0, 0) + nl.string_attr(1, "aodv") + elements
    assert nl.set_element_addresses(payload) == ["10.0.0.4", "10.0.0.7"]
    # In place, within a datagram: nothing before `start` or from `end` on is read.
    blob = elem("10.0.0.9") + payload + elem("10.0.0.8")
    at = len(elem("10.0.0.9"))
    assert nl.set_element_addresses(blob, at, at + len(payload)) == ["10.0.0.4", "10.0.0.7"]
    assert nl.set_element_addresses(blob, at, at + len(payload) - 1) == ["10.0.0.4"]
