"""The replay view: a finished run's files served as one JSON and a page, nothing else."""

import asyncio
import csv

import pytest
from aiohttp.test_utils import TestClient, TestServer

from testbed.view import replay, served, server


def write_run(d, steps=3):
    d.mkdir()
    (d / "config.json").write_text(
        '{"robots": 2, "comm_range": 5.0, "map_size": [400, 400], "display_pos": [10, 10]}'
    )
    with open(d / "positions.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["step", "x1", "y1", "x2", "y2"])
        for s in range(steps + 1):
            w.writerow([s, 1 + s, 1, 4, 1])
    (d / "links.csv").write_text("step,event,i,j\n0,add,1,2\n2,remove,1,2\n")
    (d / "coverage.csv").write_text("step,coverage\n0,0.1\n1,0.2\n2,0.3\n3,0.4\n")
    (d / "result.json").write_text(
        '{"status": "complete", "config": {"robots": 2, "comm_range": 5.0, "laser_range": 2.0}}'
    )
    (d / "display").mkdir()
    (d / "display" / "step-00002.png").write_bytes(
        served.PACKAGED_MAPS.joinpath("office.png").read_bytes()
    )
    (d / "display" / "step-00003.png").write_bytes(b"\x89PNG not really")  # not served


def test_load_reads_what_the_run_wrote(tmp_path):
    write_run(tmp_path / "r")
    data = replay.load(tmp_path / "r")
    assert data["steps"] == 3 and data["robots"] == 2 and data["map_m"] == [20.0, 20.0]
    assert data["positions"][2] == [3.0, 1.0, 4.0, 1.0]
    assert data["links"] == [[0, True, 1, 2], [2, False, 1, 2]]
    assert data["coverage"][-1] == 0.4 and data["status"] == "complete"
    with pytest.raises(replay.NotARun):
        replay.load(tmp_path)


def test_server_serves_the_page_and_the_run_and_no_other_path(tmp_path):
    write_run(tmp_path / "r")

    async def go():
        async with TestClient(TestServer(server.make_app(tmp_path / "r"))) as client:
            page = await client.get("/")
            assert page.status == 200 and "view.js" in await page.text()
            js = await client.get("/static/view.js")
            assert js.status == 200 and "api/run" in await js.text()
            data = await (await client.get("/api/run")).json()
            assert data["steps"] == 3
            for bad in ("/static/../../config.json", "/static/index.html", "/static/x.js",
                        "/runs/r/config.json", "/etc/passwd"):  # fmt: skip
                assert (await client.get(bad)).status == 404, bad
            # Empty terrain: no picture, and the page is told not to ask for one.
            assert data["map"] is False
            assert (await client.get("/map.png")).status == 404
            assert data["snapshots"] == [2, 3]
            assert (await client.get("/display.png?step=2")).status == 200
            for missing in ("3", "4"):  # not a PNG; no such snapshot
                assert (await client.get("/display.png?step=" + missing)).status == 404
            for bad in ("..%2Fconfig.json", "-1", "", "²", "1" * 12):
                assert (await client.get("/display.png?step=" + bad)).status == 400, bad

    asyncio.run(go())


def test_bind_is_localhost_unless_a_host_is_given():
    assert server.parse_bind("8470") == ("127.0.0.1", 8470)
    assert server.parse_bind("0.0.0.0:9000") == ("0.0.0.0", 9000)
    with pytest.raises(ValueError):
        server.parse_bind("localhost:http")
