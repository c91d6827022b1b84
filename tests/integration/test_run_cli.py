"""`testbed run` as a user runs it: the directory it writes into, bad input as one line
before anything exists, and what it says at the end."""

import json
import os
import socket
import subprocess
import sys

import pytest

from node.displaysteps import VIDEO_EVERY, DisplaySteps
from testbed.files.runconfig import RunConfig
from testbed.run.prepare import DEFAULT_SNAPSHOTS

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
FAST = ["--comm-range", "20", "--time-scale", "10", "--routing", "oracle", "--quiet"]


def tb_run(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "testbed.cli", "run", *args],
                          capture_output=True, text=True, cwd=REPO, timeout=600)  # fmt: skip


def one_line_error(r: subprocess.CompletedProcess, *words: str) -> None:
    assert r.returncode == 2, (r.returncode, r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    for w in words:
        assert w in lines[0], lines[0]


def tree(d) -> dict:
    return {
        os.path.relpath(os.path.join(root, f), d): os.stat(os.path.join(root, f)).st_mtime_ns
        for root, dirs, files in os.walk(d)
        for f in files + dirs
    }


def test_a_run_over_an_earlier_run_is_refused_unless_replaced(tmp_path, tb_name):
    out = str(tmp_path / "run")
    first = tb_run("--robots", "2", "--capture", "--out", out, "--name", tb_name, *FAST,
                   "--routing", "aodv")  # fmt: skip
    assert first.returncode == 0, first.stderr
    with open(os.path.join(out, "routing.json"), "w") as f:
        f.write("{}")  # as `testbed report` would have left
    before = tree(out)
    assert {"pcaps/r2.pcap", "robots/r2.json", "aodv/r2.json"} <= set(before)

    again = tb_run("--robots", "1", "--out", out, "--name", tb_name, *FAST)
    one_line_error(again, out, "holds a run", "--replace")
    assert tree(out) == before, "nothing touched"

    new = tb_run("--robots", "1", "--out", out, "--name", tb_name, "--replace", *FAST)
    assert new.returncode == 0, new.stderr
    after = tree(out)
    for old in ("pcaps", "routing.json", "robots/r2.json", "robots/r2.log", "aodv"):
        assert old not in after, old
    with open(os.path.join(out, "result.json")) as f:
        assert json.load(f)["config"]["robots"] == 1


def test_a_run_says_how_it_ended_and_names_its_steps(tmp_path, tb_name):
    out = str(tmp_path / "run")
    r = tb_run("--robots", "2", "--out", out, "--name", tb_name, *FAST)
    assert r.returncode == 0, r.stderr
    with open(os.path.join(out, "result.json")) as f:
        result = json.load(f)
    finish = [rb["finish_step"] for rb in result["robots"].values()]
    assert result["last_finish_step"] == max(finish)
    assert result["mean_finish_step"] == pytest.approx(sum(finish) / 2)
    assert result["steps"] == max(finish) + 1  # the step at which the world noticed
    assert result["status_detail"] == f"all robots finished by step {max(finish)}"
    with open(os.path.join(out, "config.json")) as f:
        assert json.load(f)["snapshots"] == [100, 250, 500, 1000, 2000]
    written = sorted(
        int(f[5:10]) for f in os.listdir(os.path.join(out, "display")) if f.startswith("step-")
    )
    assert result["display"]["snapshots"] == written and written[-1] == result["steps"]
    # The display was sent the frames of the steps it acts on and of the last step only.
    acts = DisplaySteps(RunConfig.map_period, VIDEO_EVERY, frozenset(DEFAULT_SNAPSHOTS))
    sent = [k for k in range(result["steps"]) if acts.wanted(k)] + [result["steps"]]
    assert result["fidelity"]["measures"]["display_frames"] == len(sent)
    last = r.stdout.strip().splitlines()[-1]
    assert last.startswith(f"testbed run: complete after {result['steps']} steps, coverage ")
    assert f"results in {out}" in last and f"testbed view {out}" in last


def test_an_unwritable_out_is_one_line(tmp_path, tb_name):
    (tmp_path / "file").write_text("x")
    for out in (str(tmp_path / "file" / "run"), "/proc/st-no-such-dir/run"):
        one_line_error(tb_run("--robots", "1", "--out", out, "--name", tb_name, *FAST), out)


def test_a_view_port_in_use_is_one_line_and_makes_nothing(tmp_path, tb_name):
    out = tmp_path / "run"
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        r = tb_run("--robots", "1", "--out", str(out), "--name", tb_name, "--view", str(port),
                   *FAST)  # fmt: skip
    one_line_error(r, f"--view {port}", "cannot listen")
    assert not out.exists()


def test_delay_without_netem_is_one_line_and_makes_nothing(tmp_path, tb_name):
    from topology.kernel.impair import kernel_has_netem

    if kernel_has_netem():
        pytest.skip("this kernel has sch_netem: --delay works here")
    out = tmp_path / "run"
    r = tb_run("--robots", "1", "--out", str(out), "--name", tb_name, "--delay", "10", *FAST)
    one_line_error(r, "--delay", "sch_netem")
    assert not out.exists()


def test_a_testbed_name_in_use_is_one_line_and_makes_nothing(tmp_path, tb_name):
    up = subprocess.run(
        [sys.executable, "-m", "testbed.cli", "net", "up", tb_name, "--robots", "1",
         "--comm-range", "5"], capture_output=True, text=True, cwd=REPO,
    )  # fmt: skip
    assert up.returncode == 0, up.stderr
    out = tmp_path / "run"
    one_line_error(tb_run("--robots", "1", "--out", str(out), "--name", tb_name, *FAST),
                   tb_name, "in use")  # fmt: skip
    assert not out.exists()
