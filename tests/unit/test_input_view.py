"""`testbed view` on a results directory from someone else: it serves the run's own files and
nothing else, its JSON is always valid, and what it cannot read is one line and exit 2."""

import asyncio
import contextlib
import json
import os
import socket
from pathlib import Path

import pytest
from aiohttp.test_utils import TestClient, TestServer

import testbed
from testbed import cli
from testbed.view import replay, server
from testbed.view.live import LiveFeed
from testbed.view.live import make_app as live_app

OFFICE = Path(testbed.__file__).parent / "experiments" / "maps" / "office.png"


def write_run(d, config=None, positions="step,x1,y1\n0,1,1\n1,2,1\n"):
    d.mkdir(exist_ok=True)
    conf = {"robots": 1, "comm_range": 5.0, "map_size": [400, 400]}
    (d / "config.json").write_text(json.dumps(conf if config is None else config))
    (d / "positions.csv").write_text(positions)
    return d


def strict_json(text: str):
    def refuse(name):
        raise ValueError(f"{name} is not JSON")

    return json.loads(text, parse_constant=refuse)


def get(app, *paths) -> list[tuple[int, bytes]]:
    async def go():
        async with TestClient(TestServer(app)) as client:
            out = []
            for p in paths:
                r = await client.get(p)
                out.append((r.status, await r.read()))
            return out

    return asyncio.run(go())


@pytest.mark.parametrize("named", ["/etc/shadow", "/etc/passwd", "../../../../etc/passwd"])
def test_a_map_outside_the_run_is_not_served(tmp_path, named):
    run = write_run(tmp_path / "r", {"robots": 1, "comm_range": 5.0, "map": named})
    (status, body), (_, data) = get(server.make_app(run), "/map.png", "/api/run")
    assert status == 404 and b"root:" not in body
    assert strict_json(data)["map"] is False


def test_the_view_says_in_one_line_that_a_map_is_not_served(tmp_path):
    run = write_run(tmp_path / "r", {"robots": 1, "comm_range": 5.0, "map": "/etc/shadow"})
    warned = []
    server.make_app(run, warn=warned.append)
    assert len(warned) == 1 and "/etc/shadow" in warned[0] and "not served" in warned[0]


def test_a_symlink_out_of_the_run_is_not_followed(tmp_path):
    run = write_run(tmp_path / "r", {"robots": 1, "comm_range": 5.0, "map": "map.png"})
    os.symlink("/etc/passwd", run / "map.png")
    (run / "display").mkdir()
    os.symlink("/etc/passwd", run / "display" / "step-00001.png")
    outside = tmp_path / "secret.png"  # a real PNG, but not the run's
    outside.write_bytes(OFFICE.read_bytes())
    os.symlink(outside, run / "display" / "step-00002.png")
    (status, body), (snap1, _), (snap2, _) = get(
        server.make_app(run), "/map.png", "/display.png?step=1", "/display.png?step=2"
    )
    assert (status, snap1, snap2) == (404, 404, 404) and b"root:" not in body


def test_the_runs_own_map_and_the_packaged_maps_are_served_and_only_real_pngs(
    tmp_path, monkeypatch
):
    run = write_run(tmp_path / "own")
    (run / "map.png").write_bytes(OFFICE.read_bytes())
    assert get(server.make_app(run), "/map.png")[0] == (200, OFFICE.read_bytes())
    run = write_run(tmp_path / "pkg", {"robots": 1, "comm_range": 5.0, "map": str(OFFICE)})
    assert get(server.make_app(run), "/map.png")[0][0] == 200
    # A packaged map named as the run was given it, from the repository's root.
    monkeypatch.chdir(OFFICE.parent.parent.parent.parent)
    rel = {"robots": 1, "comm_range": 5.0, "map": "testbed/experiments/maps/office.png"}
    assert get(server.make_app(write_run(tmp_path / "rel", rel)), "/map.png")[0][0] == 200
    run = write_run(tmp_path / "fake", {"robots": 1, "comm_range": 5.0, "map": "notes.png"})
    (run / "notes.png").write_text("a text file named .png")
    assert get(server.make_app(run), "/map.png")[0][0] == 404


@pytest.mark.parametrize(
    "config, positions, message",
    [
        ([1, 2, 3], None, "not a JSON object"),
        ("just a string", None, "not a JSON object"),
        ({"robots": "2", "comm_range": 5}, None, "robots is not a number"),
        ({"robots": 1, "comm_range": float("inf")}, None, "comm_range"),
        ({"robots": 1, "comm_range": 5, "map_size": [1e300, 1]}, None, "map_size"),
        ({"robots": 1, "comm_range": 5}, "step,x1,y1\n0,nan,1\n", "line 2"),
        ({"robots": 1, "comm_range": 5}, "step,x1,y1\n0,-1e308,1e308\n", "line 2"),
        ({"robots": 2, "comm_range": 5}, "step,x1,y1\n0,1,1\n", "3 columns, not 5"),
        ({"robots": 1, "comm_range": 5}, "step,x1,y1\n0,1,\x00\n", "line 2"),
    ],
)
def test_a_run_the_view_cannot_hold_is_refused_in_one_line(tmp_path, config, positions, message):
    run = write_run(tmp_path / "r", config, *(positions,) if positions else ())
    with pytest.raises(replay.NotARun, match=message) as refused:
        server.make_app(run)
    assert len(str(refused.value).splitlines()) == 1


@contextlib.contextmanager
def busy_port():
    """A port something already listens on: `testbed view` can never start serving there."""
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        yield str(busy.getsockname()[1])


def test_a_config_that_is_a_list_is_one_line_and_exit_2(tmp_path, capsys):
    run = write_run(tmp_path / "r", [1, 2, 3])
    with busy_port() as port:
        assert cli.main(["view", str(run), "--view", port]) == 2
    out, err = capsys.readouterr()
    assert out == "" and len(err.strip().splitlines()) == 1 and "not a JSON object" in err


def test_a_busy_port_is_one_line_and_exit_2_and_no_address_printed(tmp_path, capsys):
    run = write_run(tmp_path / "r")
    with busy_port() as port:
        assert cli.main(["view", str(run), "--view", port]) == 2
    out, err = capsys.readouterr()
    assert out == "" and "cannot listen there" in err and len(err.strip().splitlines()) == 1


def test_json_out_of_the_view_is_valid_whatever_the_values():
    assert strict_json(server.json_text({"a": [float("nan"), float("-inf"), 1.5]})) == {
        "a": [None, None, 1.5]
    }
    meta = {"run": "t", "robots": 2, "comm_range": float("inf"), "map_m": [float("nan"), 1.0]}
    feed = LiveFeed(meta)
    feed.publish(1, [(float("-inf"), 0.0), (1.0, 2.0)], {}, 0.5, 0, None)
    assert strict_json(server.json_text(feed.frame()))["positions"] == [None, 0.0, 1.0, 2.0]
    (status, body), *_ = get(live_app(feed, None), "/api/run")
    assert status == 200 and strict_json(body)["comm_range"] is None


@pytest.mark.parametrize("to", ["0", "3", "-1", "", "x", "²", "99999999999999999999", "1.5"])
def test_a_route_query_for_no_robot_is_http_400(to):
    feed = LiveFeed({"run": "t", "robots": 2})
    ((status, body),) = get(live_app(feed, None), f"/api/routes?to={to}")
    assert status == 400 and b"1..2" in body
