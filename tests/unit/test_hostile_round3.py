"""Issue 55, "read wrong without a word" and item 4: files of another format or shape, and
options the run refuses, refused in one line. Each case used to be read as something it is
not (a format 2 file as format 1, two captures that are one file as two robots', a header
naming robot 1 twice as robots 1 and 2), or ended in a traceback or a run that did nothing;
now each is one line naming the file (or the option) and what is wrong, exit 2, or the
capture left out and named, never a traceback and never a partial or mixed result."""

import json
import os
import struct
import subprocess
import sys
import time
import tomllib

import pytest

from common.errors import UsageError
from common.paths import PROJECT_ROOT
from node.native import unbuilt_reason
from testbed.analysis import capturefiles, pathsfig
from testbed.analysis.runs import load_runs
from testbed.files.resultfile import ResultError, RunResult
from testbed.sweep import file as sweepfile
from testbed.view import replay
from tests.unit import hostile_dirs as hd

RUN = ["run", "--robots", "2", "--comm-range", "5", "--out", "/nonexistent/never-made"]


# -- a format other than the reader's --------------------------------------------------------


@pytest.mark.parametrize("fmt", [2, 0, 99])
def test_a_result_of_another_format_is_one_line(tmp_path, capsys, fmt):
    run = hd.run_dir(tmp_path / "s")
    hd.edit_result(run, lambda d: d.update(format=fmt))
    hd.refused(["report", run], capsys, "result.json", f"format {fmt}", "format 1")
    with pytest.raises(ResultError, match="format"):
        RunResult.from_json(run)


def test_a_sweep_leaves_out_a_run_of_another_format(tmp_path, capsys):
    sweep = hd.sweep_dir(tmp_path / "sweep")
    run = sorted((sweep / "runs").iterdir())[0]
    hd.edit_result(run, lambda d: d.update(format=2))
    status, _, err = hd.testbed(["report", sweep], capsys)
    assert status == 0, err
    assert "**Left out: 1 run(s)" in (sweep / "report.md").read_text()
    assert len(load_runs(sweep)) == 3


def _sweep_json(sweep, doc):
    (sweep / "sweep.json").write_text(json.dumps(doc))


@pytest.mark.parametrize("fmt", [2, 0])
def test_a_sweep_json_of_another_format_is_one_line(tmp_path, capsys, fmt):
    sweep = hd.sweep_dir(tmp_path / "sweep")
    _sweep_json(sweep, {"format": fmt, "runs": []})
    for argv in (["report", sweep], ["sweep", "--status", sweep]):
        hd.refused(argv, capsys, "sweep.json", f"format {fmt}")


@pytest.mark.parametrize("copies", [2, 100_000])
def test_a_sweep_json_naming_a_run_twice_is_one_line(tmp_path, capsys, copies):
    sweep = hd.sweep_dir(tmp_path / "sweep")
    run_id = sorted(p.name for p in (sweep / "runs").iterdir())[0]
    _sweep_json(sweep, {"format": 1, "runs": [{"id": run_id, "status": "done"}] * copies})
    start = time.monotonic()
    for argv in (["report", sweep], ["sweep", "--status", sweep]):
        hd.refused(argv, capsys, "sweep.json", "runs[1]", run_id, "twice")
    assert time.monotonic() - start < 30


# -- captures that are one file, or not a capture ---------------------------------------------


def _captured_run(tmp_path):
    run = hd.run_dir(tmp_path / "s")
    (run / "pcaps").mkdir()
    for k in (1, 3):
        (run / "pcaps" / f"r{k}.pcap").write_bytes(hd.udp_pcap(k, 4))
    return run


@pytest.mark.parametrize("how", ["hard link", "copy"])
def test_two_captures_that_are_one_file_are_both_left_out(tmp_path, capsys, how):
    run = _captured_run(tmp_path)
    r1, r2 = run / "pcaps" / "r1.pcap", run / "pcaps" / "r2.pcap"
    if how == "hard link":
        os.link(r1, r2)
    else:
        r2.write_bytes(r1.read_bytes())
    found = capturefiles.checked(capturefiles.find(run))
    assert sorted(found.paths) == [3]
    assert "r1.pcap" in found.left_out["r2.pcap"] and "r2.pcap" in found.left_out["r1.pcap"]
    status, out, err = hd.testbed(["report", run], capsys)
    assert status == 0, err
    assert "**Captures left out**" in out and "r2.pcap (the same" in out


def test_captures_with_no_frame_may_be_alike(tmp_path):
    """Robots that sent and heard nothing: the same 24 bytes, each still its robot's."""
    run = hd.with_captures(hd.run_dir(tmp_path / "s"))
    found = capturefiles.checked(capturefiles.find(run))
    assert sorted(found.paths) == [1, 2] and not found.left_out


def _record_claiming(length: int) -> bytes:
    return hd.EMPTY_PCAP + struct.pack("<IIII", 1000, 0, length, length) + b"x" * 60


@pytest.mark.parametrize(
    ("data", "says"),
    [
        (_record_claiming(2**32 - 1), "4294967295 bytes"),
        (_record_claiming(300_000), "300000 bytes"),
        (hd.udp_pcap(1, 3)[:-10] + hd.udp_pcap(1, 1)[24:], "record 4 claims"),
    ],
    ids=["2**32-1", "beyond the snap length", "a record cut, then another"],
)
def test_a_record_longer_than_the_capture_is_left_out(tmp_path, capsys, data, says):
    run = _captured_run(tmp_path)
    (run / "pcaps" / "r2.pcap").write_bytes(data)
    found = capturefiles.checked(capturefiles.find(run))
    assert sorted(found.paths) == [1, 3] and says in found.left_out["r2.pcap"]
    status, out, err = hd.testbed(["report", run], capsys)
    assert status == 0 and "r2.pcap (" in out, err


def test_a_last_record_cut_short_is_still_read(tmp_path):
    """A run killed mid-write leaves its last record short: what comes before it counts."""
    run = _captured_run(tmp_path)
    (run / "pcaps" / "r2.pcap").write_bytes(hd.udp_pcap(2, 3)[:-10])
    found = capturefiles.checked(capturefiles.find(run))
    assert sorted(found.paths) == [1, 2, 3], found.left_out


def test_a_capture_of_more_frames_than_the_bound_is_left_out(tmp_path, monkeypatch):
    monkeypatch.setattr(capturefiles, "MAX_CAPTURE_FRAMES", 3)
    run = _captured_run(tmp_path)
    (run / "pcaps" / "r2.pcap").write_bytes(hd.udp_pcap(2, 3))
    found = capturefiles.checked(capturefiles.find(run))
    assert sorted(found.paths) == [2]
    assert "more than 3 frames" in found.left_out["r1.pcap"]


def test_a_sparse_300_mib_capture_is_refused_quickly(tmp_path, capsys):
    run = _captured_run(tmp_path)
    with open(run / "pcaps" / "r2.pcap", "wb") as f:
        f.write(hd.EMPTY_PCAP)
        f.truncate(300 << 20)  # a hole: 300 MiB of records of 0 bytes
    start = time.monotonic()
    status, out, err = hd.within(100, hd.testbed, ["report", run], capsys)
    assert status == 0, err
    assert "r2.pcap (" in out and "frames" in out
    assert time.monotonic() - start < 60


# -- a CSV header naming a column twice -------------------------------------------------------


def _view_run(d, positions):
    d.mkdir(parents=True)
    (d / "config.json").write_text(json.dumps({"robots": 2, "comm_range": 5.0}))
    (d / "positions.csv").write_text(positions)
    (d / "links.csv").write_text("step,event,i,j\n")
    return d


@pytest.mark.parametrize(
    "header", ["step,x1,y1,x1,y1", "step,x1,x1,x2,y2", "step,x2,y2,x1,y1", "step,a,b,c,d"]
)
def test_the_view_refuses_a_positions_header_not_the_teams(tmp_path, capsys, header):
    d = _view_run(tmp_path / "r", f"{header}\n0,1,1,2,2\n")
    with pytest.raises(replay.NotARun, match="positions.csv line 1"):
        replay.load(d)
    hd.refused(["view", d], capsys, "positions.csv", "line 1")


def test_the_paths_picture_refuses_a_robot_named_twice(tmp_path):
    sweep = hd.sweep_dir(tmp_path / "sweep")
    run = sorted((sweep / "runs").iterdir())[0]
    (run / "positions.csv").write_text("step,x1,y1,x1,y1\n0,1,1,2,2\n")
    with pytest.raises(pathsfig.PathsError, match="twice"):
        pathsfig.write_paths(load_runs(sweep)[0], tmp_path / "p")


# -- options and sweep files by the run's rule ------------------------------------------------


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["--laser-range", "1e-300"], "shorter than a map cell"),
        (["--laser-range", "0.01"], "shorter than a map cell"),
        (["--laser-range", "0.5", "--map-cell", "1", "--map", "m.png"], "shorter than a map cell"),
        (["--isolate", "r1:1:10000001"], "10,000,000"),
        (["--isolate", "r1:10000001:1"], "10,000,000"),
    ],
)
def test_a_run_that_could_do_nothing_is_refused(capsys, args, says):
    hd.refused(RUN + args, capsys, says)


def test_the_largest_isolation_is_taken():
    from testbed import cli
    from testbed.run.arguments import config_from_args

    argv = [*RUN, "--isolate", "r1:10000000:10000000"]
    cfg = config_from_args(cli.build_parser(["run"]).parse_args(argv))
    assert cfg.isolate[0].steps == 10_000_000


GOOD = """
[grid]
robots = [1, 2]
comm_range = [5]
laser_range = [2.0]
[run]
"""


@pytest.mark.parametrize(
    ("change", "key", "says"),
    [
        (("laser_range = [2.0]", "laser_range = [2.0, 1e-300]"), "grid.laser_range",
         "shorter than a map cell"),
        (("[run]", '[run]\nrobot = "cpp"\nmiddleware = "zenoh"'), "run.robot", "zenoh"),
        (("[run]", '[run]\nrobot = "cpp"\nmaps = "pubsub"\nmiddleware = "dds"'), "run.robot",
         "dds"),
        (("[grid]", '[grid]\nrobot = ["python", "cpp"]\nmiddleware = ["nanomsg", "zenoh"]'),
         "grid.robot", "zenoh"),
    ],
    ids=["a laser of 1e-300", "cpp with zenoh", "cpp with pubsub", "a grid of both"],
)  # fmt: skip
def test_a_sweep_file_is_checked_by_the_runs_rule(change, key, says):
    if "cpp" in change[1] and unbuilt_reason() is not None:
        pytest.skip(f"the C++ robot is not built: {unbuilt_reason()}")
    with pytest.raises(UsageError) as e:
        sweepfile.parse(tomllib.loads(GOOD.replace(*change)), "s.toml")
    assert str(e.value).startswith(f"sweep file s.toml: {key}:"), str(e.value)
    assert says in str(e.value) and "\n" not in str(e.value)


@pytest.mark.parametrize(
    ("change", "key"),
    [(("comm_range = [5]", "comm_range = [5, 5.0000001]"), "grid.comm_range"),
     (("[run]", 'map = ["a/office.png", "b/office.png"]\n[run]'), "grid.map")],
)  # fmt: skip
def test_grid_values_that_one_run_id_names_are_refused(change, key):
    """They made two runs of one id: the second was taken for done when the first was."""
    with pytest.raises(UsageError) as e:
        sweepfile.parse(tomllib.loads(GOOD.replace(*change)), "s.toml")
    assert str(e.value).startswith(f"sweep file s.toml: {key}:") and "run's id" in str(e.value)


def test_a_sweep_json_plan_the_run_would_refuse_is_one_line(tmp_path, capsys):
    sweep = hd.sweep_dir(tmp_path / "sweep")
    config = {"robots": 2, "comm_range": 5.0, "laser_range": 1e-300}
    _sweep_json(sweep, {"runs": [{"id": "a", "config": config}]})
    hd.refused(["sweep", "--status", sweep], capsys, "sweep.json", "runs[0].config", "cell")


# -- -0.0 -------------------------------------------------------------------------------------


def test_a_negative_zero_fraction_is_shown_as_zero(tmp_path, capsys):
    run = hd.run_dir(tmp_path / "s")
    keys = ("coverage_final", "deadline_miss_fraction", "deadline_miss_fraction_outside_stalls")
    hd.edit_result(run, lambda d: d.update(dict.fromkeys(keys, -0.0)))
    status, out, err = hd.testbed(["report", run], capsys)
    assert status == 0, err
    assert "-0.0" not in out and "coverage at the end: 0.0%" in out
    r = RunResult.from_json(run)
    assert all(str(getattr(r, k)) == "0.0" for k in keys)


# -- the Python robot's command line ----------------------------------------------------------


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["--robots", str(10**12)], "--robots"),
        (["--robots", "2", "--events", "/proc/self/mem"], "--events"),
        (["--robots", "2", "--events", "/nonexistent/dir/e.jsonl"], "--events"),
    ],
    ids=["10**12 robots", "events /proc/self/mem", "events in no directory"],
)
def test_the_python_robots_command_line_is_one_line(tmp_path, args, says):
    argv = [sys.executable, "-m", "node", "--robot", "r1", "--body", str(tmp_path / "none")]
    r = subprocess.run(argv + args, capture_output=True, text=True, timeout=60, cwd=PROJECT_ROOT)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2, r.stderr
    assert len(lines) == 1 and says in lines[0] and "Traceback" not in r.stderr, r.stderr
