"""The body link over a real Unix socket: hello, frames, commands, hang-up."""

import numpy as np

from node import body
from testbed.world.bodylink import BodyServer


def test_body_link_round_trip(tmp_path):
    server = BodyServer(str(tmp_path / "body.sock"))
    try:
        robot = body.BodyClient(server.path, 3)
        display = body.BodyClient(server.path, 4, body.ROLE_DISPLAY)
        server.wait_for({3}, {4}, timeout=0.2)
        assert not server.robots  # connected, but not ready yet
        robot.ready()
        display.ready()
        server.wait_for({3}, {4}, timeout=5.0)
        assert set(server.robots) == {3} and set(server.displays) == {4}
        r = np.linspace(0.1, 2.0, 8).astype(np.float32)
        assert server.send(3, body.frame(5, 1.0, 2.0, 0.0, r, 123.0))
        assert server.send(4, body.frame(5, 10.0, 10.0, 0.0, None), display=True)
        kind, f = robot.recv(timeout=5.0)
        assert kind == "frame" and f.step == 5 and np.allclose(f.ranges, r) and f.sent == 123.0
        assert display.recv(timeout=5.0)[1].ranges.size == 0
        assert robot.recv(timeout=0.01) is None
        robot.send(body.cmd(5, (1.5, 2.0)))
        robot.send(body.done(5))
        got = []
        for _ in range(50):
            got += server.poll(0.05)
            if len(got) >= 2:
                break
        assert got == [(3, ("cmd", 5, (1.5, 2.0))), (3, ("done", 5))]
        server.send(3, body.END)
        assert robot.recv(timeout=5.0) == ("end",)
        robot.close()
        for _ in range(20):
            server.poll(0.05)
        assert 3 not in server.robots  # the hang-up is noticed
        assert not server.send(3, body.END)
        display.close()
    finally:
        server.close()
