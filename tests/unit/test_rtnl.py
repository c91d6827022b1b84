"""topology.kernel.rtnl without the kernel: the AF_BRIDGE dump's parser on hand-built messages."""

import socket
import struct

import pytest

from topology.kernel import rtnl

NEWLINK, DONE, ERROR = 16, 3, 2


def _nla(kind: int, body: bytes) -> bytes:
    raw = struct.pack("=HH", 4 + len(body), kind) + body
    return raw + b"\0" * (-len(raw) % 4)


def _port(index: int, name: str, state: int | None, oper: int) -> bytes:
    attrs = _nla(rtnl.IFLA_IFNAME, name.encode() + b"\0") + _nla(rtnl.IFLA_OPERSTATE, bytes([oper]))
    if state is not None:
        attrs += _nla(
            rtnl.IFLA_PROTINFO | rtnl.NLA_F_NESTED, _nla(rtnl.IFLA_BRPORT_STATE, bytes([state]))
        )
    body = struct.pack("=BxHiII", socket.AF_BRIDGE, 1, index, 0, 0) + attrs
    return struct.pack("=LHHLL", 16 + len(body), NEWLINK, 2, 1, 0) + body


def _done() -> bytes:
    return struct.pack("=LHHLLi", 20, DONE, 2, 1, 0, 0)


class FakeSocket:
    """Answers one dump request with the given datagrams."""

    def __init__(self, datagrams: list[bytes]):
        self.datagrams = list(datagrams)
        self.sent: list[bytes] = []

    def send(self, data: bytes) -> int:
        self.sent.append(bytes(data))
        return len(data)

    def recv(self, _size: int) -> bytes:
        return self.datagrams.pop(0)


def test_bridge_ports_reads_name_state_and_operstate_across_datagrams():
    sock = FakeSocket([
        _port(10001002, "l1x2", 3, rtnl.IF_OPER_UP) + _port(10002001, "l2x1", 0, 2),
        _port(2000001, "rp1", None, rtnl.IF_OPER_UP) + _done(),
    ])  # fmt: skip
    ports = rtnl.bridge_ports(sock)
    assert ports == {
        10001002: ("l1x2", 3, rtnl.IF_OPER_UP),
        10002001: ("l2x1", 0, 2),
        2000001: ("rp1", -1, rtnl.IF_OPER_UP),
    }
    length, mtype, flags, _, _ = struct.unpack_from("=LHHLL", sock.sent[0])
    assert (length, mtype) == (32, 18)  # RTM_GETLINK with an ifinfomsg
    assert flags & 0x300 == 0x300  # NLM_F_DUMP
    assert sock.sent[0][16] == socket.AF_BRIDGE


def test_bridge_ports_raises_on_an_error_answer():
    sock = FakeSocket([struct.pack("=LHHLLi", 36, ERROR, 0, 1, 0, -1) + b"\0" * 16])
    with pytest.raises(rtnl.NetlinkBatchError, match="bridge port dump"):
        rtnl.bridge_ports(sock)


def _answer(seq: int, index: int, state: int) -> bytes:
    slave = _nla(rtnl.IFLA_INFO_SLAVE_DATA, _nla(rtnl.IFLA_BRPORT_STATE, bytes([state])))
    attrs = _nla(rtnl.IFLA_IFNAME, b"l1x2\0") + _nla(
        rtnl.IFLA_LINKINFO, _nla(4, b"bridge\0") + slave
    )
    attrs += _nla(rtnl.IFLA_OPERSTATE, bytes([rtnl.IF_OPER_UP]))
    body = struct.pack("=BxHiII", socket.AF_UNSPEC, 1, index, 0, 0) + attrs
    return struct.pack("=LHHLL", 16 + len(body), NEWLINK, 0, seq, 0) + body


def test_port_states_reads_the_bridge_slave_data_and_skips_absent_interfaces():
    missing = struct.pack("=LHHLLi", 36, ERROR, 0, 2, 0, -19) + b"\0" * 16  # ENODEV
    sock = FakeSocket([_answer(1, 10001002, 3) + missing])
    assert rtnl.port_states(sock, [10001002, 77]) == {10001002: ("l1x2", 3, rtnl.IF_OPER_UP)}
    assert len(sock.sent[0]) == 2 * 32
