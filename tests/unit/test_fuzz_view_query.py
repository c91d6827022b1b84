"""Property tests of the view's query parameters and paths (Hypothesis), against the real
aiohttp apps of a replay and of a live view: whatever a request says, exactly one of two
outcomes: an answer (200, or 404 for something the run does not have) whose JSON is strict,
or HTTP 400 with one line saying why. Never a 500, never a file the run did not write."""

import asyncio
import csv
import json

import pytest
from aiohttp.test_utils import TestClient, TestServer
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st
from yarl import URL

from testbed.view import served, server
from testbed.view.live import LiveFeed
from testbed.view.live import make_app as live_app

FUZZ = dict(deadline=None, database=None)
OFFICE = served.PACKAGED_MAPS / "office.png"
ROBOTS = 3

VALUES = st.one_of(
    st.text(st.characters(blacklist_categories=("Cs",)), max_size=24),
    st.integers(-(10**12), 10**12).map(str),
    st.sampled_from(["0", "1", "2", "3", "4", "00002", "²", "1e3", " 1", "1 ", "0x1", "-0"]),
)


@pytest.fixture(scope="module")
def clients(tmp_path_factory):
    """(loop, replay client, live client), one of each for every example."""
    d = tmp_path_factory.mktemp("run")
    (d / "config.json").write_text(json.dumps({"robots": ROBOTS, "comm_range": 5.0}))
    with open(d / "positions.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["step"] + [f"{a}{k}" for k in range(1, ROBOTS + 1) for a in "xy"])
        w.writerows([s] + [float(s)] * 2 * ROBOTS for s in range(3))
    (d / "display").mkdir()
    (d / "display" / "step-00002.png").write_bytes(OFFICE.read_bytes())
    (d / "map.png").write_bytes(OFFICE.read_bytes())
    feed = LiveFeed({"run": "t", "robots": ROBOTS, "comm_range": 5.0}, run_dir=d)
    feed.publish(1, [(float("nan"), 1.0)] * ROBOTS, {(1, 2): None}, 0.5, 0, None)
    loop = asyncio.new_event_loop()

    async def start(app) -> TestClient:
        client = TestClient(TestServer(app))
        await client.start_server()
        return client

    made = [loop.run_until_complete(start(a)) for a in (server.make_app(d), live_app(feed, None))]
    yield loop, *made
    for c in made:
        loop.run_until_complete(c.close())
    loop.close()


FETCH_TIMEOUT_S = 30.0


def fetch(loop, client, path: str, params=None) -> tuple[int, bytes]:
    async def go():
        r = await client.get(path, params=params)
        if r.content_type == "text/event-stream":  # the live view's stream never ends
            first = await r.content.readuntil(b"\n\n")  # its first event
            r.close()
            return r.status, first
        return r.status, await r.read()

    # A server that never answers fails the test rather than stalling the suite.
    return loop.run_until_complete(asyncio.wait_for(go(), FETCH_TIMEOUT_S))


def check(status: int, body: bytes) -> None:
    assert status in (200, 400, 404), status
    if status == 400:
        assert len(body.decode().strip().splitlines()) == 1, body


@settings(max_examples=400, **FUZZ)
@given(VALUES)
def test_a_snapshot_query_is_answered_or_refused(clients, step):
    loop, replay_client, live_client = clients
    for client in (replay_client, live_client):
        status, body = fetch(loop, client, "/display.png", {"step": step})
        check(status, body)
        if status == 200:
            assert step.isascii() and int(step) == 2 and body == OFFICE.read_bytes()


@settings(max_examples=600, **FUZZ)
@given(VALUES)
def test_a_route_query_is_refused_unless_a_robot_and_a_network(clients, to):
    loop, _, live_client = clients
    status, body = fetch(loop, live_client, "/api/routes", {"to": to})
    check(status, body)
    robot = to.isascii() and to.isdigit() and 1 <= int(to) <= ROBOTS
    assert status == (404 if robot else 400)  # a robot, but no network to ask: 404


@settings(max_examples=300, **FUZZ)
@given(st.text(st.characters(blacklist_categories=("Cs",)), max_size=30))
@example("\r/0")  # found on 2026-11-27: the client made it "//0"
@example("api/live")  # found on 2026-11-27: the live stream, read to its end, never ended
def test_any_path_is_the_page_or_nothing_and_json_is_strict(clients, path):
    loop, replay_client, live_client = clients
    target = "/" + path.lstrip("/")
    # A tab or line break cannot be part of an HTTP request target, and the client's URL
    # parsing drops them ("/\r/0" becomes "//0", a host): nothing a server is ever asked.
    assume(not set(target) & set("\t\r\n") and not URL(target).absolute)
    for client in (replay_client, live_client):
        status, body = fetch(loop, client, target)
        check(status, body)
        if status == 200 and path.strip("/") == "api/run":
            json.loads(body, parse_constant=lambda c: pytest.fail(f"{c} in /api/run"))
