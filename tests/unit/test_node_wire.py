"""Messages between robots and to the body: encodings, validation, duplicate suppression."""

import numpy as np
import pytest

from node import body, wire
from node.flood import WINDOW, DuplicateCache
from node.grid import FREE, OCC


def test_flood_header_round_trip_and_relay_rewrite():
    h = wire.FloodHeader(wire.KIND_MAP, 16, 3, 1234, 99, sender=3, neighbours=(5, 2))
    data = wire.pack_flood(h, b"payload")
    h2, p = wire.unpack_flood(data)
    assert h2 == wire.FloodHeader(wire.KIND_MAP, 16, 3, 1234, 99, 3, (2, 5)) and p == b"payload"
    assert wire.flood_ids(data) == (16, 3, 1234, 3)
    h3, p3 = wire.unpack_flood(wire.relayed(data, 7, 5, [1, 3, 4]))
    assert (h3.ttl, h3.origin, h3.seq, h3.step) == (7, 3, 1234, 99) and p3 == b"payload"
    assert (h3.sender, h3.neighbours) == (5, (1, 3, 4))


def test_flood_header_bytes_laid_out_by_hand():
    h = wire.FloodHeader(wire.KIND_BEACON, 2, 0x0102, 0x03040506, 7, sender=9, neighbours=(1,))
    assert wire.pack_flood(h, b"") == (
        b"RMF2" + bytes([2, 2, 1, 2, 3, 4, 5, 6, 0, 0, 0, 7]) + bytes([0, 9, 1, 0, 1])
    )


@pytest.mark.parametrize(
    "bad",
    [
        b"",
        b"RMF",
        b"XXXX" + bytes(15),
        b"RMF1" + bytes(15),  # the old format
        b"RMF2" + bytes(14) + b"\x03" + bytes(4),  # claims 3 neighbours, carries 2
    ],
)
def test_malformed_floods_are_rejected(bad):
    with pytest.raises(ValueError):
        wire.unpack_flood(bad)


def test_map_payload_round_trip_with_offset():
    t = np.zeros((30, 40), dtype=np.uint8)
    t[5:10, 7:20] = FREE
    t[9, 19] = OCC
    payload = wire.pack_map(1.5, 2.5, t, r_off=100, c_off=50)
    m = wire.unpack_map(payload, (400, 400))
    assert (m.r0, m.c0) == (105, 57) and m.cells.shape == (5, 13)
    assert (m.x, m.y) == (1.5, 2.5)
    assert np.array_equal(m.cells, t[5:10, 7:20])
    with pytest.raises(ValueError):
        wire.unpack_map(payload, (100, 100))  # does not fit a smaller map


def test_goal_messages_parse_and_validate():
    m = wire.parse_msg(wire.goal_msg(2, 10, (1.0, 2.0), 3.5, fallback=True), 5)
    assert m["k"] == "goal" and m["goal"] == (1.0, 2.0) and m["cost"] == 3.5 and m["fallback"]
    r = wire.parse_msg(wire.replan_msg(1, 11, (4.0, 4.0)), 5)
    assert r["k"] == "replan" and r["from"] == 1
    for bad in [
        b"not json",
        b"[]",
        b'{"k": "goal", "from": 9, "step": 1, "goal": [1, 2], "cost": 1}',  # no such robot
        b'{"k": "goal", "from": 1, "step": -1, "goal": [1, 2], "cost": 1}',
        b'{"k": "goal", "from": 1, "step": 1, "goal": [1], "cost": 1}',
        b'{"k": "goal", "from": 1, "step": 1, "goal": [1, 2]}',
        b'{"k": "shout", "from": 1, "step": 1, "goal": [1, 2]}',
    ]:
        with pytest.raises(ValueError):
            wire.parse_msg(bad, 5)


def test_duplicate_cache():
    c = DuplicateCache()
    assert not c.seen(1, 5)
    assert c.seen(1, 5)
    assert not c.seen(1, 3)  # overtaken on another path: still new
    assert not c.seen(2, 5)  # another origin
    assert not c.seen(1, 5 + 3 * WINDOW)
    assert c.seen(1, 5)  # far below the highest: treated as old


def test_body_messages_round_trip():
    r = np.array([1.0, np.inf, 0.5], dtype=np.float32)
    kind, f = body.parse(body.frame(7, 1.5, 2.5, 0.1, r))
    assert kind == "frame" and f.step == 7 and np.array_equal(f.ranges, r)
    assert body.parse(body.cmd(7, (1.0, 2.0))) == ("cmd", 7, (1.0, 2.0))
    assert body.parse(body.cmd(8, None)) == ("cmd", 8, None)
    assert body.parse(body.done(9)) == ("done", 9)
    assert body.parse(body.hello(3, body.ROLE_DISPLAY)) == ("hello", 3, body.ROLE_DISPLAY)
    assert body.parse(body.END) == ("end",)
    for bad in [b"", b"Z", b"F" + bytes(3), body.frame(1, 0, 0, 0, r)[:-2]]:
        with pytest.raises(ValueError):
            body.parse(bad)


def test_beacon_round_trip():
    assert wire.unpack_beacon(wire.pack_beacon(10.0, 5.5)) == (10.0, 5.5)
    with pytest.raises(ValueError):
        wire.unpack_beacon(b"short")
