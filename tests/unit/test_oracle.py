"""Oracle routing: shortest paths from the link set, and the kernel requests that carry them."""

import socket
import struct

from topology.oracle import RTPROT_ORACLE, changes, delete_request, route_request, shortest_routes


def test_shortest_routes_on_a_chain_and_a_diamond():
    chain = shortest_routes({(1, 2), (2, 3), (3, 4)}, 4)
    assert chain[1] == {2: (2, 1), 3: (2, 2), 4: (2, 3)}
    assert chain[4] == {3: (3, 1), 2: (3, 2), 1: (3, 3)}
    # 1 - {2, 3} - 4: two equal paths, the lower-numbered next hop wins, every time.
    diamond = shortest_routes({(1, 2), (1, 3), (2, 4), (3, 4)}, 4)
    assert diamond[1][4] == (2, 2) and diamond[4][1] == (2, 2)
    # Without 1-2 the route goes round through 3.
    assert shortest_routes({(1, 3), (2, 4), (3, 4)}, 4)[1][4] == (3, 2)


def test_unreachable_robots_have_no_route():
    routes = shortest_routes({(1, 2)}, 3)
    assert 3 not in routes[1] and routes[3] == {}


def test_changes_are_a_diff_and_ignore_hop_count_only_changes():
    old = {2: (2, 1), 3: (2, 2), 4: (2, 3)}
    new = {2: (2, 1), 3: (3, 1), 5: (3, 2)}
    assert changes(old, new) == ([(3, 3), (5, 3)], [4])
    assert changes(old, {2: (2, 1), 3: (2, 2), 4: (2, 9)}) == ([], [])


def test_route_requests_encode_what_ip_route_would():
    req = route_request(5, 2, 10)
    length, mtype, flags, _, _ = struct.unpack_from("=LHHLL", req)
    assert length == len(req) and mtype == 24  # RTM_NEWROUTE
    assert flags & 0x100 and flags & 0x400  # NLM_F_REPLACE | NLM_F_CREATE
    fam, plen, _, _, table, proto, scope, rtype, rflags = struct.unpack_from("=BBBBBBBBI", req, 16)
    assert (fam, plen, table, proto, rtype) == (socket.AF_INET, 32, 254, RTPROT_ORACLE, 1)
    assert scope == 0 and rflags == 4  # universe, onlink: a gateway on a /32 link
    assert socket.inet_aton("10.0.0.5") in req and socket.inet_aton("10.0.0.2") in req
    direct = route_request(2, 2, 10)
    assert struct.unpack_from("=BBBBBBBBI", direct, 16)[6] == 253  # scope link, no gateway
    assert len(direct) == len(req) - 8
    assert struct.unpack_from("=LH", delete_request(4))[1] == 25  # RTM_DELROUTE
