"""Careless and hostile input to the real command (`.venv/bin/testbed`), as root.

One table: each row is an input that once ended in a traceback, a hang, a runaway or mixed
results (traces, maps, lasers, sweep files and directories, a Ctrl-C), and the command line
that gives it. Each must end with exit status 2 (130 for the Ctrl-C, 1 when a part that
started fails), exactly one line on stderr and no traceback, and leave nothing behind: no
namespace of the row's testbed name, no sweep directory or `.sweep.lock` the refusal made,
an earlier sweep's directory exactly as it was.
"""

import os
import re
import signal
import struct
import subprocess
import sys
import time
import zlib
from pathlib import Path

import pytest

from topology.kernel import netns

REPO = Path(__file__).resolve().parents[2]
TESTBED = str(REPO / ".venv" / "bin" / "testbed")
OFFICE = REPO / "testbed" / "experiments" / "maps" / "office.png"

SWEEP = """
[grid]
robots = [1]
comm_range = [5]
laser_range = [2.0]
[run]
max_steps = 50
"""
# A stand-in for `testbed run` that only writes a finished run's files (the earlier sweep of
# the resume row: what is tested is the refusal of the second sweep, not runs).
STANDIN = """
import json, os, sys
out = sys.argv[sys.argv.index("--out") + 1]
os.makedirs(out)
cfg = {"robots": 1, "comm_range": 5.0, "laser_range": 2.0}
json.dump({"config": cfg}, open(os.path.join(out, "config.json"), "w"))
json.dump({"status": "complete", "config": cfg}, open(os.path.join(out, "result.json"), "w"))
"""


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def huge_png(path: Path, side: int = 20000) -> None:
    z = zlib.compressobj(9)
    block = (b"\x00" + b"\xff" * (side // 8)) * 1000
    idat = b"".join(z.compress(block) for _ in range(side // 1000)) + z.flush()
    ihdr = struct.pack(">IIBBBBB", side, side, 1, 0, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + _chunk(b"IDAT", idat)
                     + _chunk(b"IEND", b""))  # fmt: skip


def ns2(leg: str) -> str:
    return (
        f"$node_(0) set X_ 0\n$node_(0) set Y_ 0\n$node_(1) set X_ 5\n$node_(1) set Y_ 0\n{leg}\n"
    )


def write(tmp: Path, name: str, text: str | bytes) -> str:
    p = tmp / name
    p.write_bytes(text.encode() if isinstance(text, str) else text)
    return str(p)


def fifo(tmp: Path) -> str:
    p = tmp / "trace.fifo"
    os.mkfifo(p)
    return str(p)


def truncated_png(tmp: Path) -> str:
    data = OFFICE.read_bytes()
    return write(tmp, "cut.png", data[: len(data) // 2])


def earlier_sweep(tmp: Path) -> str:
    """A finished sweep of SWEEP in tmp/done (made with the stand-in); returns its dir."""
    out = tmp / "done"
    sweep_file = write(tmp, "first.toml", SWEEP)
    standin = write(tmp, "standin.py", STANDIN)
    env = dict(os.environ, TESTBED_SWEEP_RUN_COMMAND=f"{sys.executable} {standin}")
    r = subprocess.run([TESTBED, "sweep", sweep_file, "--out", str(out)], env=env, cwd=REPO,
                       capture_output=True, text=True, timeout=60)  # fmt: skip
    assert r.returncode == 0, r.stderr
    return str(out)


NET_UP = ["net", "up", "{name}", "--comm-range", "10"]
RUN = ["run", "--robots", "1", "--comm-range", "5", "--name", "{name}", "--out", "{tmp}/run"]

# (row id, argv with {name} {tmp} and {x} placeholders, how to make {x}, exit status,
#  a word the one line must hold)
ROWS = [
    ("8-ns2-node-id-1e11", [*NET_UP, "--mobility", "{x}"],
     lambda t: write(t, "id.ns2", "$node_(100000000000) set X_ 1\n"
                                   "$node_(100000000000) set Y_ 1\n"), 2,
     "node id 100000000000"),
    ("8-one-id-1e15", [*NET_UP, "--mobility", "{x}"],
     lambda t: write(t, "id.one", "0 0 0 0\n1 1e15 3 3\n"), 2, "node id 1e15"),
    ("8-dev-zero", [*NET_UP, "--mobility", "/dev/zero"], None, 2, "not a regular file"),
    ("8-fifo", [*NET_UP, "--mobility", "{x}"], fifo, 2, "not a regular file"),
    ("8-time-1e12", [*NET_UP, "--mobility", "{x}"],
     lambda t: write(t, "t.ns2", ns2('$ns_ at 1e12 "$node_(0) setdest 1 1 1"')), 2,
     "past the limit of 1e6 s"),
    ("8-tick-1e-9", [*NET_UP, "--mobility", "{x}", "--tick", "1e-9"],
     lambda t: write(t, "ok.ns2", ns2('$ns_ at 1 "$node_(0) setdest 1 1 1"')), 2,
     "tick must be at least 0.001"),
    ("9-laser-100", [*RUN, "--laser-range", "100"], None, 2, "at most 30"),
    ("9-laser-past-the-diagonal", [*RUN, "--laser-range", "29"], None, 2, "diagonal"),
    ("10-grid-100k", ["sweep", "{x}", "--out", "{tmp}/big"],
     lambda t: write(t, "big.toml", SWEEP.replace("[run]", "runs = 100000\n[run]")), 2,
     "100,000 runs"),
    ("11-speed-1e-320", [*NET_UP, "--mobility", "{x}"],
     lambda t: write(t, "slow.ns2", ns2('$ns_ at 1 "$node_(0) setdest 10 0 1e-320"')), 2,
     "would arrive at inf s"),
    ("11-player-dies", [*NET_UP, "--robots", "2", "--mobility", "{x}", "--links-out", "{tmp}"],
     lambda t: write(t, "ok.ns2", ns2('$ns_ at 1 "$node_(0) setdest 1 1 1"')), (1, 2),
     ("the trace player exited", "--links-out")),
    ("12-binary-sweep-file", ["sweep", "{x}", "--out", "{tmp}/bin"],
     lambda t: write(t, "bin.toml", b"[grid]\n\xff\xfe\x00garbage"), 2, "not a text file"),
    ("13-png-20000", [*RUN, "--map", "{x}"], lambda t: huge_png(t / "big.png") or t / "big.png",
     2, "20000 x 20000 pixels"),
    ("13-png-20000-los", [*NET_UP, "--robots", "2", "--range-model", "los", "--map", "{x}"],
     lambda t: huge_png(t / "big.png") or t / "big.png", 2, "20000 x 20000 pixels"),
    ("13-map-directory", [*RUN, "--map", "{tmp}"], None, 2, "is a directory"),
    ("13-truncated-png", [*RUN, "--map", "{x}"], truncated_png, 2, "truncated"),
    ("13-sweep-out-file", ["sweep", "{x}", "--out", "{x}"],
     lambda t: write(t, "s.toml", SWEEP), 2, "is not a directory"),
    ("13-one-header-6-fields", [*NET_UP, "--mobility", "{x}"],
     lambda t: write(t, "h.one", "0 1 2 3 4 5\n0 0 0 0\n0 1 1 1\n"), 2, "outside the header"),
    ("13-sweep-missing-map", ["sweep", "{x}", "--out", "{tmp}/maps"],
     lambda t: write(t, "m.toml", SWEEP.replace("[run]", '[run]\nmap = "gone.png"')), 2,
     "does not exist"),
    ("5-resume-another-sweep", ["sweep", "{x}", "--out", "{tmp}/done", "--resume"],
     lambda t: earlier_sweep(t) and write(t, "second.toml", SWEEP.replace("[1]", "[2]")), 2,
     "resume it with its own sweep file"),
]  # fmt: skip


def our_namespaces(name: str) -> list[str]:
    return [ns for ns in netns.list_names() if f"-{name}-" in ns]


def snapshot(d: Path) -> dict[str, int]:
    return {str(p): p.stat().st_mtime_ns for p in d.rglob("*")}


@pytest.mark.parametrize("row", ROWS, ids=[r[0] for r in ROWS])
def test_hostile_input_is_one_line_and_leaves_nothing(tb_name, tmp_path, row):
    _, argv, make, status, word = row
    x = str(make(tmp_path)) if make else ""
    before = snapshot(tmp_path)
    args = [a.format(name=tb_name, tmp=tmp_path, x=x) for a in argv]
    r = subprocess.run([TESTBED, *args], cwd=REPO, capture_output=True, text=True, timeout=60)
    lines = r.stderr.strip().splitlines()
    assert r.returncode in (status if isinstance(status, tuple) else (status,)), r.stderr[-800:]
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr[-800:]
    assert any(w in lines[0] for w in (word if isinstance(word, tuple) else (word,))), lines[0]
    assert not our_namespaces(tb_name)
    assert not (tmp_path / "run").exists()  # a refused run made no directory
    if args[0] == "sweep":  # a refused sweep makes and touches nothing, not even a lock file
        assert snapshot(tmp_path) == before


def _default_sigint():
    """The child starts with SIGINT's default action, whatever ours is, and with SIGINT
    blocked, as `env --block-signal=INT` starts it: a Ctrl-C during the interpreter's own
    start then waits for the command's guard (testbed.console), which unblocks it. Without
    the block, a Ctrl-C in those first ~20 ms (longer on a loaded machine) is Python's
    traceback, before any of the command's code runs."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})


@pytest.mark.parametrize("after", [0.0, 0.1, 0.3, 0.6])
def test_ctrl_c_soon_after_start_is_one_line_and_130(tb_name, tmp_path, after):
    out = tmp_path / "run"
    p = subprocess.Popen([TESTBED, *[a.format(name=tb_name, tmp=tmp_path) for a in RUN]],
                         cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         preexec_fn=_default_sigint)  # fmt: skip
    time.sleep(after)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=60)
    # A run that reached its steps first wrote its progress line (testbed.run.progress: in a
    # log, one at the first step, then every 10 s): that is the run's output, not the error.
    lines = [ln for ln in err.strip().splitlines() if not re.match(r"step \d+/\d+  ", ln)]
    assert p.returncode == 130, err[-800:]
    assert len(lines) == 1 and "interrupted" in lines[0] and "Traceback" not in err, err[-800:]
    assert not our_namespaces(tb_name)
    # Either nothing was made yet, or the run kept its record of being interrupted.
    assert not out.exists() or '"interrupted"' in (out / "result.json").read_text()
