"""A live Python robot and a live C++ robot survive a hostile world (issue 55): each robot runs
alone in a network namespace of its own (unique name, removed even on failure), its body link
served by this test in the world's place. Between well-formed frames the stand-in sends the
round's hostile frames (tests/unit/test_hostile_body_flood.py's corpus: NaN, ±inf, 3.4e38,
-100 and just off the map as position, a NaN heading, an infinite send time, another ray
count), then END.

Each robot must answer the good frames, exit 0 and count exactly the hostile ones in its
summary's `malformed` (the summary event that becomes robots/rK.json). Before the fix the
Python robot ended with status 3 on the first of them. Root only (namespaces); the C++ half is
skipped where build/tb-robot was not built.
"""

from __future__ import annotations

import json
import math
import os
import socket
import subprocess
import sys
import time
import uuid
from pathlib import Path

import numpy as np
import pytest

from node import body
from node.native import TB_ROBOT, unbuilt_reason

pytestmark = pytest.mark.skipif(os.geteuid() != 0, reason="needs root (network namespaces)")
REPO = Path(__file__).resolve().parents[2]
ROWS, COLS, CELL, RAYS = 100, 120, 0.1, 90  # a 12 x 10 m map
STEP_S = 0.02  # wall seconds between frames (time scale 5)


def scan(n: int = RAYS) -> np.ndarray:
    return np.full(n, np.inf, np.float32)


HOSTILE = [
    body.frame(0, math.nan, 5.0, 0.0, scan(), 0.0),
    body.frame(0, 5.0, math.inf, 0.0, scan(), 0.0),
    body.frame(0, 3.4e38, 5.0, 0.0, scan(), 0.0),
    body.frame(0, -100.0, 5.0, 0.0, scan(), 0.0),
    body.frame(0, COLS * CELL + 0.01, 5.0, 0.0, scan(), 0.0),
    body.frame(0, 5.0, ROWS * CELL, 0.0, scan(), 0.0),
    body.frame(0, 5.0, 5.0, math.nan, scan(), 0.0),
    body.frame(0, 5.0, 5.0, 0.0, scan(), math.inf),
    body.frame(0, 5.0, 5.0, 0.0, scan(RAYS - 1), 0.0),
    body.frame(0, 5.0, 5.0, 0.0, scan(0), 0.0),
]


def robot_argv(kind: str, sock: str, events: str) -> list[str]:
    common = ["--robot", "r1", "--robots", "1", "--body", sock, "--events", events,
              "--map-size", f"{ROWS}x{COLS}", "--cell", str(CELL), "--laser-range", "1.0",
              "--laser-rays", str(RAYS), "--time-scale", "5", "--iface", "",
              "--bind", "127.0.0.1"]  # fmt: skip
    if kind == "cpp":
        return [str(TB_ROBOT), *common]
    return [sys.executable, "-m", "node", *common]


def serve(conn: socket.socket, steps: int) -> int:
    """The world's side: wait for HELLO, send `steps` frames with the hostile ones spread
    among them (hostile frame i with the step of good frame i + 1), then END. Returns the
    CMDs the robot sent."""
    conn.settimeout(60)
    assert body.parse(conn.recv(body.MAX_DATAGRAM))[0] == "hello"
    conn.settimeout(0)
    cmds = 0
    for step in range(1, steps + 1):
        t = time.monotonic()
        data = body.frame(step, 5.0, 5.0, 0.0, scan(), t)
        conn.send(data)
        if step - 1 < len(HOSTILE):
            bad = bytearray(HOSTILE[step - 1])
            bad[1:5] = step.to_bytes(4, "big")
            conn.send(bytes(bad))
        while time.monotonic() < t + STEP_S:
            try:
                msg = body.parse(conn.recv(body.MAX_DATAGRAM))
                cmds += msg[0] == "cmd"
            except BlockingIOError:
                time.sleep(0.002)
    conn.send(body.END)
    return cmds


@pytest.mark.parametrize("kind", ["python", "cpp"])
def test_a_live_robot_survives_hostile_body_frames(tmp_path, kind):
    if kind == "cpp" and not TB_ROBOT.is_file():
        pytest.skip(f"no C++ robot: {unbuilt_reason() or 'build/tb-robot is missing'}")
    ns = "hw" + uuid.uuid4().hex[:8]
    sock_path = str(tmp_path / "body.sock")
    events = tmp_path / "r1.events.jsonl"
    srv = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    srv.bind(sock_path)
    srv.listen(1)
    srv.settimeout(60)
    proc = None
    subprocess.run(["ip", "netns", "add", ns], check=True)
    try:
        subprocess.run(["ip", "-n", ns, "link", "set", "lo", "up"], check=True)
        log = open(tmp_path / "r1.log", "w")  # noqa: SIM115 (closed below)
        proc = subprocess.Popen(["ip", "netns", "exec", ns, *robot_argv(kind, sock_path,
                                 str(events))], cwd=REPO, stdout=log, stderr=log)  # fmt: skip
        conn, _ = srv.accept()
        cmds = serve(conn, steps=60)
        status = proc.wait(timeout=60)
        conn.close()
        log.close()
        text = (tmp_path / "r1.log").read_text()
        assert status == 0, text[-3000:]
        assert "Traceback" not in text, text[-3000:]
        summary = next(e for e in reversed([json.loads(x) for x in events.open()])
                       if e["e"] == "summary")  # fmt: skip
        assert summary.get("robot_impl", "python") == kind
        assert summary["malformed"] == len(HOSTILE), (summary["malformed"], text[-3000:])
        assert summary["frames"] >= 60 - summary.get("frames_skipped", 0) - 5
        assert cmds > 0
    finally:
        if proc is not None and proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)
        srv.close()
        subprocess.run(["ip", "netns", "del", ns], check=False)
    assert ns not in subprocess.run(["ip", "netns", "list"], capture_output=True,
                                    text=True).stdout  # fmt: skip
