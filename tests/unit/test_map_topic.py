"""Maps over publish/subscribe (node.messaging.maps, .zenoh_maps, .dds_maps) on loopback.

Three messengers (robots 1 and 2, the display 3), each with the map topic on its own session
or participant, as a run makes them: every one publishes maps in flood form and receives
every other's, never its own; the counters say what was published, received and from whom;
a publication while no subscriber is known fails at once; close() leaves no Python thread.
Addresses as tests/unit/test_messaging_zenoh_dds.py: Zenoh's nodes are 127.0.0.k, Cyclone's
share 127.0.0.1 and differ by participant index (shared_stack=3).
"""

import select
import threading
import time

import numpy as np
import pytest

from node import wire
from tests.unit.test_messaging_zenoh_dds import RECONNECT_MS, SEND_TIMEOUT_MS, _free_port

TEAM = (1, 2, 3)


@pytest.fixture(params=["zenoh", "dds"])
def kind(request) -> str:
    pytest.importorskip(
        {"zenoh": "zenoh", "dds": "cyclonedds"}[request.param],
        reason=f"the {request.param} middleware's Python package is not installed",
    )
    return request.param


def _messenger(kind: str, me: int, port: int):
    if kind == "zenoh":
        from node.messaging.zenoh import ZenohMessenger

        return ZenohMessenger(me, f"127.0.0.{me}", port, lambda j: f"127.0.0.{j}", TEAM,
                              SEND_TIMEOUT_MS, RECONNECT_MS)  # fmt: skip
    from node.messaging.dds import DdsMessenger

    return DdsMessenger(me, "127.0.0.1", port, lambda j: "127.0.0.1", TEAM, SEND_TIMEOUT_MS,
                        RECONNECT_MS, shared_stack=len(TEAM))  # fmt: skip


def _map_payload(k: int, n: int) -> bytes:
    cells = np.full((3, 4), n % 3, dtype=np.uint8)
    return wire.pack_map(float(k), float(n), cells, k, n)


def _collect(topics, want: dict, timeout: float = 10.0) -> dict:
    """Each topic's received floods (header, payload) until it has `want[me]` maps."""
    got = {t.me: [] for t in topics}
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if all(sum(h.kind == wire.KIND_MAP for h, _ in got[t.me]) >= want[t.me] for t in topics):
            break
        ready, _, _ = select.select([t.fileno() for t in topics], [], [], 0.1)
        for t in topics:
            if t.fileno() in ready:
                got[t.me] += t.receive()
    return got


def test_maps_go_to_every_subscriber_and_never_back(kind):
    port = _free_port()
    ms = [_messenger(kind, k, port) for k in TEAM]
    try:
        topics = [m.map_topic() for m in ms]
        assert all(m.map_topic() is t for m, t in zip(ms, topics, strict=True))  # one each
        # Wait until every reader has matched every writer: maps sent before that are lost.
        deadline = time.monotonic() + 15.0
        while True:
            for t in topics:
                t.originate(wire.KIND_BEACON, 0, wire.pack_beacon(0.0, 0.0))
            time.sleep(0.05)
            heard = {t.me: {h.origin for h, _ in t.receive()} for t in topics}
            if all(set(TEAM) - {k} <= heard[k] for k in TEAM):
                break
            assert time.monotonic() < deadline, heard
        # Seq numbers go on from the beacons: remember where the maps start.
        first = {t.me: t.seq + 1 for t in topics}
        maps = 5
        for n in range(maps):
            for t in topics[:2]:  # the robots publish maps; the display only subscribes
                t.originate(wire.KIND_MAP, 10 * n, _map_payload(t.me, n))
            time.sleep(0.02)  # one map period: KEEP_LAST 1 keeps one map per sender
        got = _collect(topics, {1: maps, 2: maps, 3: 2 * maps})
        for t in topics:
            floods = [(h, p) for h, p in got[t.me] if h.kind == wire.KIND_MAP]
            senders = {k for k in (1, 2) if k != t.me}
            assert {h.origin for h, _ in floods} == senders  # never its own
            for k in senders:
                mine = [(h, p) for h, p in floods if h.origin == k]
                assert [h.seq for h, _ in mine] == list(range(first[k], first[k] + maps))
                assert [h.step for h, _ in mine] == [10 * n for n in range(maps)]
                assert [p for _, p in mine] == [_map_payload(k, n) for n in range(maps)]
                assert all(h.ttl == 1 and h.sender == k for h, _ in mine)
            stats = t.stats.as_dict()
            assert stats["transport"] == "pubsub"
            assert stats["received_from"] == {f"r{k}": maps for k in sorted(senders)}
            assert stats["received"] == maps * len(senders)
            size = len(got[t.me][-1][1]) + 1  # payload sizes differ; bytes are whole floods
            assert stats["bytes_received"] >= stats["received"] * size
        for t in topics[:2]:
            s = t.stats
            assert (s.published, s.failed) == (maps, 0)
            assert s.bytes_published > maps * 16
            assert s.blocked_s >= s.blocked_max_s > 0
            assert s.blocked_max_s < SEND_TIMEOUT_MS / 1000 + 0.05
        assert all(t.counts["own"] == 0 for t in topics)
    finally:
        for m in ms:
            m.close()


def test_a_map_without_subscribers_fails_at_once_and_close_leaves_no_thread(kind):
    python_before = set(threading.enumerate())
    port = _free_port()
    m = _messenger(kind, 1, port)  # alone: its teammates never come
    try:
        t = m.map_topic()
        t0 = time.monotonic()
        t.originate(wire.KIND_MAP, 0, _map_payload(1, 0))
        assert time.monotonic() - t0 < SEND_TIMEOUT_MS / 1000 + 0.05
        assert (t.stats.published, t.stats.failed) == (0, 1)
        assert t.counts["send_failed"] == 1
        assert t.receive_raw() == []
    finally:
        m.close()
        m.close()
    t.originate(wire.KIND_MAP, 1, _map_payload(1, 1))  # after close: refused, no error
    assert t.stats.failed == 2
    assert t.receive_raw() == []
    deadline = time.monotonic() + 2.0  # a callback thread may be ending as close returns
    while not set(threading.enumerate()) <= python_before and time.monotonic() < deadline:
        time.sleep(0.05)
    assert set(threading.enumerate()) <= python_before
