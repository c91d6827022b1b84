"""Pure helpers of the daemon: the ICMP error it injects, the one it reads back about its own
messages, the address filter for peers."""

import socket
import struct

import pytest

from aodv import packet as wire
from aodv.daemon import Daemon, _checksum, icmp_host_unreachable, quoted_datagram
from aodv.params import Params


def udp_packet(src, dst, payload=b"hello world", ports=(40000, 5555)):
    udp = struct.pack("!HHHH", *ports, 8 + len(payload), 0) + payload
    hdr = struct.pack(
        "!BBHHHBBH4s4s", 0x45, 0, 20 + len(udp), 1, 0, 64, 17, 0,
        socket.inet_aton(src), socket.inet_aton(dst),
    )  # fmt: skip
    return hdr + udp


def test_icmp_host_unreachable_quotes_header_and_8_bytes():
    orig = udp_packet("10.0.0.1", "10.0.0.99")
    pkt = icmp_host_unreachable("10.0.0.1", orig)
    assert _checksum(pkt[:20]) == 0  # IP header checksum valid
    assert pkt[9] == socket.IPPROTO_ICMP
    assert pkt[12:16] == socket.inet_aton("10.0.0.1") and pkt[16:20] == orig[12:16]
    icmp = pkt[20:]
    assert icmp[0] == 3 and icmp[1] == 1  # destination unreachable, host unreachable
    assert _checksum(icmp) == 0
    assert icmp[8:] == orig[:28]
    assert struct.unpack("!H", pkt[2:4])[0] == len(pkt)


def test_peer_addresses_outside_the_network_are_malformed():
    d = Daemon("r1", "wlan0", Params(), None, "10.0.0.0/16")
    d._check_addresses("10.0.0.2", wire.Rreq(1, "10.0.0.5", 0, "10.0.0.1", 1))
    for src, msg in [
        ("10.0.0.2", wire.Rreq(1, "8.8.8.8", 0, "10.0.0.1", 1)),
        ("10.0.0.2", wire.Rrep("10.0.0.5", 0, "224.0.0.1", 0)),
        ("10.0.0.2", wire.Rerr((("10.0.255.255", 1),))),
        ("192.168.1.1", wire.RrepAck()),
    ]:
        with pytest.raises(wire.MalformedPacket):
            d._check_addresses(src, msg)


def kernel_unreachable(original: bytes, icmp_type: int = 3) -> bytes:
    """What the kernel hands a raw ICMP socket when ARP for `original`'s next hop failed: an
    IP packet from the robot to itself, ICMP type 3 code 1, quoting the whole datagram."""
    icmp = bytes([icmp_type, 1, 0, 0, 0, 0, 0, 0]) + original
    hdr = struct.pack(
        "!BBHHHBBH4s4s", 0x45, 0xC0, 20 + len(icmp), 7, 0, 64, 1, 0,
        socket.inet_aton("10.0.0.2"), socket.inet_aton("10.0.0.2"),
    )  # fmt: skip
    return hdr + icmp


def test_quoted_datagram_finds_our_untransmitted_messages_only():
    rrep = wire.encode(wire.Rrep("10.0.0.2", 1, "10.0.0.77", 6000))
    ours = udp_packet("10.0.0.2", "10.0.0.77", rrep, (654, 654))
    assert quoted_datagram(kernel_unreachable(ours), "10.0.0.2") == (8 + len(rrep), rrep)
    assert wire.decode(quoted_datagram(kernel_unreachable(ours), "10.0.0.2")[1]).type_name == "RREP"
    # someone else's, another port, another ICMP type, truncated: not ours to count
    assert quoted_datagram(kernel_unreachable(ours), "10.0.0.3") is None
    other_port = udp_packet("10.0.0.2", "10.0.0.77", rrep, (40000, 654))
    assert quoted_datagram(kernel_unreachable(other_port), "10.0.0.2") is None
    assert quoted_datagram(kernel_unreachable(ours, icmp_type=11), "10.0.0.2") is None
    full = kernel_unreachable(ours)
    for cut in (0, 1, 10, 20, 28, 40, 50):
        assert quoted_datagram(full[:cut], "10.0.0.2") is None


def test_every_daemon_attribute_is_declared_in_init():
    """A reader of Daemon.__init__ sees every attribute the daemon will ever have."""
    import ast

    import aodv.daemon

    tree = ast.parse(open(aodv.daemon.__file__).read())
    (cls,) = [n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "Daemon"]
    assigned: dict[str, set[str]] = {}
    for f in cls.body:
        if isinstance(f, ast.FunctionDef):
            for n in ast.walk(f):
                if isinstance(n, (ast.Assign, ast.AnnAssign, ast.AugAssign)):
                    targets = n.targets if isinstance(n, ast.Assign) else [n.target]
                    for t in targets:
                        for e in ast.walk(t):
                            if (
                                isinstance(e, ast.Attribute)
                                and getattr(e.value, "id", "") == "self"
                            ):
                                assigned.setdefault(f.name, set()).add(e.attr)
    declared = assigned.pop("__init__")
    late = {f"{fn}: self.{a}" for fn, attrs in assigned.items() for a in attrs - declared}
    assert not late, sorted(late)
    assert {"routes", "tun", "sock", "core"} <= declared
