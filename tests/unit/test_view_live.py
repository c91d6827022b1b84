"""The live view's server: frames published by the step loop reach a browser's stream, and
the server ends cleanly; publishing never waits for anyone."""

import json
import socket
import time
import urllib.request

from testbed.view.live import LiveFeed, LiveServer


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_published_frames_stream_to_a_client_and_the_server_stops():
    meta = {"run": "t", "robots": 2, "comm_range": 5.0, "map_m": [20.0, 20.0],
            "display": [10, 10], "status": "running", "steps": 0, "positions": [],
            "links": [], "coverage": []}  # fmt: skip
    feed = LiveFeed(meta)
    srv = LiveServer(feed, str(free_port()))
    try:
        base = f"http://127.0.0.1:{srv.port}"
        assert json.loads(urllib.request.urlopen(base + "/api/run").read())["live"] is True
        t0 = time.perf_counter()
        for step in range(1, 200):
            feed.publish(step, [(1.0, 2.0), (3.0, 4.0)], {(1, 2): None}, 0.5, 0, 10.0)
        assert time.perf_counter() - t0 < 0.05  # a reference stored a step, nothing more
        stream = urllib.request.urlopen(base + "/api/live", timeout=5)
        frame = json.loads(stream.readline().decode().removeprefix("data: "))
        assert frame["step"] == 199 and frame["links"] == [[1, 2]]
        assert frame["positions"] == [1.0, 2.0, 3.0, 4.0]
        feed.publish(200, [(1.5, 2.0), (3.0, 4.0)], {}, 0.6, 1, 10.0)
        stream.readline()  # the blank line ending the first event
        second = json.loads(stream.readline().decode().removeprefix("data: "))
        assert second["step"] == 200 and second["links"] == [] and second["missed"] == 1
    finally:
        srv.stop()
    assert not srv.thread.is_alive()
    with socket.socket() as s:  # nobody listens there any more
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.bind(("127.0.0.1", srv.port))


def test_robot_events_give_goals_and_message_rates(tmp_path):
    from testbed.view.live import RobotEvents

    log = tmp_path / "r1.events.jsonl"
    log.write_text(
        '{"e":"plan","step":0,"cause":"start","goal":[2.5,0.5]}\n'
        '{"e":"send","step":2,"kind":"map"}\n{"e":"rec'
    )  # a line being written
    ev = RobotEvents({1: str(log)})
    ev.poll()
    assert ev.goals == {1: [2.5, 0.5]} and ev.rate is None
    with open(log, "a") as f:
        f.write(
            'v","step":3}\n{"e":"send","step":4,"kind":"goal"}\n'
            '{"e":"plan","step":20,"cause":"timer","goal":[4.0,1.0]}\n'
        )
    ev._last -= 1.0  # a second later
    ev.poll()
    assert ev.goals == {1: [4.0, 1.0]} and 0.5 < ev.rate < 1.5  # one send in about a second
