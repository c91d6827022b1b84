"""The world's compiled share of the body links (native/stepcore/bodylink.cc) against its Python
twin in testbed.world.bodylink, over real Unix sockets: the same frames byte for byte, and the
same commands, other messages, malformed counts and hang-ups."""

import contextlib
import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from node import body, stepcore
from testbed.world import bodylink
from testbed.world.bodylink import BodyServer

pytestmark = pytest.mark.skipif(not stepcore.NATIVE, reason="the step core is not built")


@contextlib.contextmanager
def team(tmp_path, n: int, display: bool = True):
    """A server with robots 1..n (and a display n + 1) connected and ready."""
    server = BodyServer(str(tmp_path / "body.sock"))
    clients = [body.BodyClient(server.path, k) for k in range(1, n + 1)]
    if display:
        clients.append(body.BodyClient(server.path, n + 1, body.ROLE_DISPLAY))
    try:
        for c in clients:
            c.ready()
        server.wait_for(set(range(1, n + 1)), {n + 1} if display else set(), timeout=5.0)
        yield server, clients
    finally:
        for c in clients:
            c.close()
        server.close()


finite = st.floats(-500.0, 500.0, width=32)
ranges_f = st.one_of(st.floats(0.0, 40.0, width=32), st.just(float("inf")))


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 6), step=st.integers(0, 2**32 - 1), now=st.floats(0, 1e7),
       n_rays=st.sampled_from([0, 1, 7, 180]), data=st.data())  # fmt: skip
def test_frames_are_the_python_frames_byte_for_byte(tmp_path_factory, n, step, now, n_rays, data):
    xyt = np.array(data.draw(st.lists(st.tuples(finite, finite, finite), min_size=n, max_size=n)),
                   dtype=np.float64)  # fmt: skip
    xyt += data.draw(st.sampled_from([0.0, 1e-9, 0.1]))  # not always float32 already
    flat = data.draw(st.lists(ranges_f, min_size=n * n_rays, max_size=n * n_rays))
    ranges = np.array(flat, dtype=np.float32).reshape(n, n_rays)
    has = np.array(data.draw(st.lists(st.sampled_from([0, 1]), min_size=n, max_size=n)), np.int8)
    live = np.array(data.draw(st.lists(st.booleans(), min_size=n, max_size=n)), dtype=bool)
    with team(tmp_path_factory.mktemp("f"), n, display=False) as (server, clients):
        server.send_frames(step, now, xyt, ranges, has, live)
        for i, c in enumerate(clients):
            if not live[i]:
                assert not c.pending()
                continue
            x, y, theta = xyt[i].tolist()
            r = ranges[i] if has[i] else np.full(n_rays, np.inf, np.float32)
            assert c.sock.recv(body.MAX_DATAGRAM) == body.frame(step, x, y, theta, r, now)
            assert not c.pending()


def test_a_full_socket_misses_its_frames_and_the_others_get_theirs(tmp_path):
    with team(tmp_path, 2, display=False) as (server, clients):
        xyt, ranges = np.zeros((2, 3)), np.zeros((2, 4000), np.float32)
        has, live = np.ones(2, np.int8), np.ones(2, bool)
        for step in range(300):  # 16 kB frames: robot 1's socket, never read, fills up
            server.send_frames(step, 0.0, xyt, ranges, has, live)
            assert clients[1].recv(timeout=1.0)[1].step == step
        queued = 0
        while clients[0].pending():
            clients[0].sock.recv(body.MAX_DATAGRAM)
            queued += 1
        assert 0 < queued < 300


# What a robot may send: commands, "done", and junk of every kind (as a hostile peer).
message = st.one_of(
    st.builds(body.cmd, st.integers(0, 2**32 - 1), st.none() | st.tuples(finite, finite)),
    st.builds(body.done, st.integers(0, 2**32 - 1)),
    st.binary(max_size=40),
    st.builds(
        lambda s, go: struct.pack("!cIBff", b"C", s, go, 1.0, 2.0),
        st.integers(0, 9),
        st.integers(2, 255),
    ),  # fmt: skip
    st.builds(lambda b: b"C" + b, st.binary(max_size=20)),
)


def per_robot(got: list) -> dict:
    """Each robot's messages: its commands as they come to (the largest step, the last
    target), and its other messages in order."""
    out: dict = {}
    for k, msg in got:
        cmds, others = out.setdefault(k, [None, []])
        if msg[0] == "cmd":
            step = msg[1] if cmds is None else max(cmds[0], msg[1])
            out[k][0] = (step, msg[2])
        else:
            others.append(msg)
    return out


@settings(max_examples=40, deadline=None)
@given(sends=st.lists(st.tuples(st.integers(0, 4), message), max_size=30),
       hang_up=st.sets(st.integers(0, 4), max_size=2))  # fmt: skip
def test_take_is_poll_come_to(tmp_path_factory, sends, hang_up):
    """sc_body_take and BodyServer.poll(0.0) on the same datagrams from four robots and a
    display: the same commands (as they come to), other messages, malformed count and
    hang-ups."""
    results = []
    for compiled in (True, False):
        with team(tmp_path_factory.mktemp("t"), 4) as (server, clients):
            saved = bodylink.stepcore.lib
            if not compiled:
                bodylink.stepcore.lib = None
            try:
                for i, data in sends:
                    if data:  # an empty datagram reads as a hang-up
                        clients[i].sock.send(data)
                for i in hang_up:
                    clients[i].sock.close()
                got = server.take(4)
            finally:
                bodylink.stepcore.lib = saved
            results.append((per_robot(got), server.malformed, sorted(server.robots),
                            sorted(server.displays)))  # fmt: skip
    assert results[0] == results[1]


def test_take_leaves_what_does_not_fit_for_the_next_step(tmp_path, monkeypatch):
    monkeypatch.setattr(bodylink, "OTHERS_BYTES", 8 + 65536 + 20)  # room for two "done"s
    with team(tmp_path, 1, display=False) as (server, clients):
        for s in range(5):
            clients[0].sock.send(body.done(s))
        clients[0].sock.send(body.cmd(7, (1.0, 2.0)))
        first = server.take(1)
        assert first == [(1, ("done", 0)), (1, ("done", 1))]
        second = server.take(1)
        assert second == [(1, ("done", 2)), (1, ("done", 3))]
        third = server.take(1)
        assert third == [(1, ("done", 4)), (1, ("cmd", 7, (1.0, 2.0)))]
        assert server.take(1) == []
