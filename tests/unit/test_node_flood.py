"""Flooding's relay rules (node.flood) on loopback sockets with a fake clock: what a robot
rebroadcasts in blind and in self-pruning mode."""

import socket
import time

import pytest

from node import wire
from node.flood import Flooder


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


@pytest.fixture
def rig():
    """A flooder for robot 2 on loopback whose broadcasts land in `sink`."""
    made = []

    def make(mode: str):
        clock = Clock()
        f = Flooder(2, 0, iface=None, mode=mode, hold=1.0, clock=clock)
        sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sink.bind(("127.0.0.1", 0))
        sink.settimeout(0.05)
        f.dest = sink.getsockname()
        src = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        made.extend((f, sink, src))
        port = f.sock.getsockname()[1]

        def deliver(origin, seq, sender, neighbours, ttl=16):
            h = wire.FloodHeader(wire.KIND_MAP, ttl, origin, seq, 5, sender, tuple(neighbours))
            src.sendto(wire.pack_flood(h, b"map"), ("127.0.0.1", port))
            time.sleep(0.01)
            return f.receive()

        def relays():
            out = []
            while True:
                try:
                    out.append(wire.unpack_flood(sink.recv(65535))[0])
                except TimeoutError:
                    return out

        return f, clock, deliver, relays

    yield make
    for s in made:
        s.close()


def test_blind_flooding_relays_every_new_flood_once(rig):
    f, _, deliver, relays = rig("blind")
    assert [h.seq for h, _ in deliver(1, 1, 1, [2, 3, 4])] == [1]
    assert deliver(1, 1, 3, [1, 2]) == []  # a duplicate: not delivered again
    (r,) = relays()
    assert (r.origin, r.seq, r.ttl, r.sender, r.neighbours) == (1, 1, 15, 2, (1,))
    assert f.counts["relayed"] == 1 and f.counts["duplicate"] == 1


def test_self_pruning_relays_only_for_neighbours_the_sender_does_not_hear(rig):
    f, clock, deliver, relays = rig("pruned")
    deliver(1, 1, 1, [2, 3])  # I hear only robot 1: nobody needs my copy
    assert relays() == [] and f.counts["pruned"] == 1
    deliver(4, 1, 4, [2])  # robot 4's own flood: 1 and 3 are not 4's neighbours
    assert [r.neighbours for r in relays()] == [(1, 4)]
    deliver(1, 2, 1, [2, 3])  # robot 4 hears me but not robot 1: it needs my copy
    assert [(r.origin, r.seq) for r in relays()] == [(1, 2)]
    deliver(1, 3, 1, [2, 3, 4])  # robot 1 reached 4 itself
    assert relays() == []
    clock.t += 1.5  # robot 4 unheard for longer than the hold time: forgotten
    assert f.neighbours() == []
    deliver(1, 4, 1, [2])
    assert relays() == []


def test_last_hop_and_own_floods_are_not_relayed(rig):
    f, _, deliver, relays = rig("blind")
    assert len(deliver(1, 1, 1, [], ttl=1)) == 1
    assert deliver(2, 7, 3, []) == []  # my own flood, relayed back to me
    assert relays() == []


def test_unknown_mode_is_refused():
    with pytest.raises(ValueError, match="flooding mode"):
        Flooder(2, 0, iface=None, mode="gossip")
