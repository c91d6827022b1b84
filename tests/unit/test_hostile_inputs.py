"""Issue 40, items 4 to 7 beyond result files: run options without an upper bound, the
environment switches, the Python API's errors, the view's malformed requests and files, and
terminal escapes in what report and view print."""

import asyncio
import json
import logging
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from aiohttp.test_utils import TestServer

from common import envswitch
from common.errors import UsageError
from common.paths import PROJECT_ROOT
from testbed import console
from testbed.net import movers
from testbed.view import replay, server
from tests.unit import hostile_dirs as hd
from topology.spec import Impairment, NetworkSpec

RUN = ["run", "--robots", "2", "--comm-range", "5", "--out", "/nonexistent/never-made"]


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["--laser-rays", "100000000"], "at most 10000"),
        (["--snapshots", "-5"], "--snapshots"),
        (["--snapshots", ",".join(map(str, range(200)))], "at most 100"),
        (["--time-scale", "1e-300"], "at least 0.01"),
        (["--time-scale", "1e9"], "at most 1000"),
        (["--kill", "r1:99999999999999999999999"], "--kill"),
        (["--isolate", "r1:1:99999999999999"], "--isolate"),
        (["--max-steps", "10000000000"], "at most"),
        (["--display-pos", "nan,1"], "finite"),
        (["--comm-range", "1e300"], "at most"),
        (["--delay", "1e12"], "at most"),
    ],
)
def test_every_numeric_run_option_is_bounded(capsys, args, says):
    hd.refused(RUN + args, capsys, says)


def test_the_bounds_are_in_the_help():
    from testbed.files.runconfig import OPTIONS

    for opt in OPTIONS:
        if opt.kind in (int, float) and opt.parse is None:
            assert opt.maximum is not None, f"{opt.name} has no upper bound"
            assert f"<= {opt.maximum:g}" in opt.help_text().replace("%%", "%")


@pytest.mark.parametrize(
    ("name", "value"),
    [("TESTBED_REALTIME", "false"), ("TESTBED_STEPCORE", "nmupy"), ("TESTBED_REALTIME", "2")],
)
def test_an_environment_switch_with_an_unknown_value_is_refused(monkeypatch, capsys, name, value):
    monkeypatch.setenv(name, value)
    monkeypatch.setattr("sys.argv", ["testbed", "view", "/nonexistent"])
    assert console.main() == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert f"{name}='{value}' is not one of" in line
    with pytest.raises(UsageError):
        envswitch.value(name)


def test_a_robot_started_by_hand_refuses_an_unknown_switch_in_one_line():
    """`python -m node` reads the switches while its modules load: one line, exit 2."""
    env = {**os.environ, "TESTBED_STEPCORE": "nmupy"}
    r = subprocess.run([sys.executable, "-m", "node", "--robot", "r1", "--robots", "1",
                        "--body", "/nonexistent"], capture_output=True, text=True, env=env,
                       timeout=60)  # fmt: skip
    assert r.returncode == 2, r.stderr
    (line,) = r.stderr.strip().splitlines()
    assert line == "node: TESTBED_STEPCORE='nmupy' is not one of compiled, numpy"


@pytest.mark.parametrize("value", ["/tmp/libstepcore.so", "build/../../libstepcore.so"])
def test_a_step_core_library_outside_build_is_refused_in_one_line(value):
    """TESTBED_STEPCORE_LIBRARY (the sanitized build its test loads) names a library every
    process of a run loads, root's included: only a file in the project's build/ is taken;
    another is refused by `testbed` and by a robot started by hand, one line, exit 2."""
    env = {**os.environ, "TESTBED_STEPCORE_LIBRARY": value}
    for argv in (
        ["-m", "testbed", "view", "/nonexistent"],
        ["-m", "node", "--robot", "r1", "--robots", "1", "--body", "/nonexistent"],
    ):
        r = subprocess.run([sys.executable, *argv], capture_output=True, text=True, env=env,
                           timeout=60)  # fmt: skip
        assert r.returncode == 2, r.stderr
        (line,) = r.stderr.strip().splitlines()
        assert line.endswith(f"TESTBED_STEPCORE_LIBRARY='{value}' is not a file in "
                             f"{Path(PROJECT_ROOT, 'build').resolve()}"), line  # fmt: skip


@pytest.mark.parametrize(("name", "value", "got"), [("TESTBED_REALTIME", "0", "0"),
                                                    ("TESTBED_STEPCORE", "NumPy", "numpy"),
                                                    ("TESTBED_REALTIME", "", "1")])  # fmt: skip
def test_known_switch_values_are_taken(monkeypatch, name, value, got):
    monkeypatch.setenv(name, value)
    assert envswitch.value(name) == got


@pytest.mark.parametrize(
    "kw",
    [
        {"comm_range": "5"},
        {"time_scale": "1"},
        {"map_cell": "0.05"},
        {"comm_range": True},
        {"wall_loss_pct": "5"},
        {"positions": 5},
        {"capture_dir": 5},
    ],  # fmt: skip
)
def test_the_api_raises_value_error_for_a_string_number(kw):
    args = {"name": "demo", "positions": ((0, 0),), "comm_range": 5.0, **kw}
    with pytest.raises(ValueError):
        NetworkSpec(**args)
    with pytest.raises(ValueError):
        Impairment(loss_pct="5")


@pytest.mark.parametrize("where", ["/proc/zz", "/proc/x.csv", "/etc/passwd/x"])
def test_a_capture_or_links_directory_is_tried_for_writing(where):
    with pytest.raises(UsageError, match="cannot write|not a directory"):
        movers.check_writable_dir(where, f"--capture {where}")


def test_sweep_view_on_a_busy_port_makes_nothing(tmp_path, capsys):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        out = tmp_path / "never"
        hd.refused(["sweep", "x.toml", "--out", out, "--view", str(port)], capsys, "cannot listen")
    assert not out.exists()


# -- the view ---------------------------------------------------------------------------------


def _view_run(d, links="step,event,i,j\n", positions="step,x1,y1,x2,y2\n0,1,1,2,2\n1,1,1,2,2\n"):
    d.mkdir(parents=True)
    (d / "config.json").write_text(json.dumps({"robots": 2, "comm_range": 5.0}))
    (d / "positions.csv").write_text(positions)
    (d / "links.csv").write_text(links)
    return d


@pytest.mark.parametrize(
    ("links", "positions", "says"),
    [
        ("step,event,i,j\n0,add,1,1\n", None, "itself"),
        ("step,event,i,j\n7,add,1,2\n", None, "'7'"),
        (None, "step,x1,y1,x2,y2\nbanana,1,1,2,2\n", "banana"),
        (None, "step,x1,y1,x2,y2\n1e400,1,1,2,2\n", "1e400"),
        (None, "step,x1,y1,x2,y2\n0,1,1,2,2\n5,1,1,2,2\n", "not 1"),
    ],
)
def test_the_view_refuses_links_and_steps_the_run_cannot_have(tmp_path, capsys, links, positions,
                                                              says):  # fmt: skip
    kw = {k: v for k, v in (("links", links), ("positions", positions)) if v is not None}
    d = _view_run(tmp_path / "r", **kw)
    with pytest.raises(replay.NotARun, match=says):
        replay.load(d)
    hd.refused(["view", d], capsys, says)


def test_a_malformed_request_is_one_log_line(tmp_path, caplog):
    app = server.make_app(_view_run(tmp_path / "r"))
    bad = [b"GET / HTTP/1.1\r\nContent-Length: abc\r\n\r\n", b"BLAH\x01 /\r\n\r\n",
           b"GET /\x00 HTTP/1.1\r\n\r\n"]  # fmt: skip

    async def go():
        async with TestServer(app) as srv:
            for request in bad:
                reader, writer = await asyncio.open_connection(srv.host, srv.port)
                writer.write(request)
                await writer.drain()
                assert (await reader.read(100)).startswith(b"HTTP/1.")  # answered 400
                writer.close()

    with caplog.at_level(logging.ERROR, logger="aiohttp.server"):
        asyncio.run(go())
    records = [r for r in caplog.records if r.name == "aiohttp.server"]
    assert 2 <= len(records) <= len(bad)  # aiohttp answers a bad method without a log record
    for r in records:
        assert r.exc_info is None and "\n" not in r.getMessage()
        assert "Error handling request" in r.getMessage()


# -- terminal escapes ------------------------------------------------------------------------


def test_status_detail_and_run_names_are_printed_escaped(tmp_path, capsys):
    run = hd.run_dir(tmp_path / "s")
    hd.edit_result(run, lambda d: d.update(status="failed", status_detail="\x1b]0;pwned\x07x"))
    named = run.rename(run.parent / "r\x1b[2Jx")
    status, out, err = hd.testbed(["report", named], capsys)
    assert status == 0, err
    assert "\x1b" not in out and "\x1b" not in err and "\x07" not in out
    assert "\\x1b]0;pwned\\x07x" in out and "r\\x1b[2Jx" in out


def test_an_error_naming_a_file_is_printed_escaped(tmp_path, capsys):
    hd.refused(["report", tmp_path / "a\x1b[2J\nb"], capsys, "a\\x1b[2J\\nb")


# -- sweep files, maps, capture directories ---------------------------------------------------


def test_a_nul_in_a_sweep_files_map_is_one_line(tmp_path):
    from testbed.sweep import command
    from testbed.sweep import file as sweepfile

    f = tmp_path / "s.toml"
    f.write_text('[grid]\nrobots = [1]\ncomm_range = [5.0]\nlaser_range = [2.0]\n'
                 'map = ["a\\u0000b.png"]\n')  # fmt: skip
    with pytest.raises(UsageError, match="map"):
        command._check_maps(sweepfile.load(f))


def test_a_sweep_file_with_a_bom_says_so(tmp_path):
    from testbed.sweep import file as sweepfile

    f = tmp_path / "s.toml"
    f.write_bytes(b"\xef\xbb\xbf[grid]\nrobots = [1]\n")
    with pytest.raises(UsageError, match="byte-order mark"):
        sweepfile.load(f)


def test_a_transparent_background_is_free_space(tmp_path):
    import cv2
    import numpy as np

    from topology.inputs import pngmap

    img = np.zeros((20, 20, 4), np.uint8)  # transparent black: free space as a viewer shows it
    img[5:8, 5:8] = (0, 0, 0, 255)  # an opaque black wall
    cv2.imwrite(str(tmp_path / "m.png"), img)
    grey = pngmap.read_gray(str(tmp_path / "m.png"))
    assert (grey < 128).sum() == 9


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ('{"routing": "aodv", "time_scale": -1}', "time_scale"),
        ('{"routing": "aodv", "time_scale": 1e308}', "time_scale"),
        ('{"routing": "x\\u001b[2J"}', "routing"),
        ("[" * 10_000 + "]" * 10_000, "nested"),
    ],
    ids=["negative scale", "1e308 scale", "unknown routing", "deep"],
)
def test_metrics_refuses_a_network_json_it_cannot_use(tmp_path, capsys, text, says):
    d = tmp_path / "cap"
    (d / "daemons").mkdir(parents=True)
    (d / "r1.pcap").write_bytes(hd.EMPTY_PCAP)
    (d / "daemons" / "network.json").write_text(text)
    line = hd.refused(["metrics", d], capsys, "network.json", says)
    assert "\x1b" not in line
