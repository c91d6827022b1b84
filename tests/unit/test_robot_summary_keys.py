"""Both robot programs write one summary (docs/robot-contract.md, section 4): the same keys,
nested ones too, in the last event of their event log, which testbed/run/results.py makes
robots/rK.json of.

Each program runs through test_robot_body_link's test world (a Unix socket, no namespace:
80 frames of an empty world, then END) and its summary is read back from its event log.
Their keys are compared level by level. Some dicts count what happened, one key per kind of
thing seen (sends and receipts by message kind, flood verdicts, busy seconds by part,
latencies by what was timed): there the two robots, which took the same steps and plans
here, must still agree on the keys both have, and each key must be one the robot's reference
counts (COUNTED) so that a misspelt kind shows. The summary's events_failed counts what a
full disk cost the event log (node/events.py; native/robot/events.cc alike): with their log
on /dev/full both robots run on and say so once, in the same words.
"""

import logging
import os
import socket
import subprocess
import sys
import time

import numpy as np
import pytest

from node import body, summary
from node.events import EventLog
from node.native import TB_ROBOT, unbuilt_reason
from testbed.run.results import SUMMARY_KEYS
from tests.unit.test_robot_body_link import RAYS, REPO, drive, free_port

# The summary's counters: each the kinds it may count, a key only once one happened.
COUNTED = {
    "sent": {"goal", "replan", "map"},
    "received": {"goal", "replan", "map", "beacon"},
    "send_failed": {"goal", "replan"},
    "flood": {"malformed", "forged", "duplicate", "relayed", "pruned", "send_failed"},
    "busy_s": {"motion", "plan", "merge", "share"},
    "latency_ms": {"delivery", "answer"},
}


def key_differences(py: dict, cc: dict, where: str = "summary") -> list[str]:
    """Where the two summaries' keys differ ([] when nowhere), as `where.key: python only`,
    `where.key: C++ only` or, in a counter, `where.key: not a kind it counts`, looking into
    every dict both hold under one key. A counter's key that one robot lacks is no
    difference (it counts what happened)."""
    out = []
    counted = COUNTED.get(where.removeprefix("summary."))
    for k in sorted(set(py) | set(cc)):
        if counted is not None and k not in counted:
            out.append(f"{where}.{k}: not a kind it counts")
        elif k not in cc or k not in py:
            if counted is None:
                out.append(f"{where}.{k}: {'python' if k in py else 'C++'} only")
        elif isinstance(py[k], dict) and isinstance(cc[k], dict):
            out += key_differences(py[k], cc[k], f"{where}.{k}")
        elif isinstance(py[k], dict) or isinstance(cc[k], dict):
            out.append(f"{where}.{k}: a dict in one robot only")
    return out


def type_differences(py, cc, where: str = "summary") -> list[str]:
    """Where the two summaries' values differ in JSON type (int, float, str, bool, None,
    list, dict) under a key both have, looking into every dict and list both hold; []
    when nowhere."""
    pairs: list[tuple[str, object, object]] = []
    if isinstance(py, dict) and isinstance(cc, dict):
        pairs = [(f"{where}.{k}", py[k], cc[k]) for k in sorted(set(py) & set(cc))]
    elif isinstance(py, list) and isinstance(cc, list):
        pairs = [(f"{where}[{i}]", a, b) for i, (a, b) in enumerate(zip(py, cc, strict=False))]
    elif type(py) is not type(cc):
        return [f"{where}: {type(py).__name__} in python, {type(cc).__name__} in C++"]
    return [d for w, a, b in pairs for d in type_differences(a, b, w)]


def fields_of(event: dict) -> dict:
    """A summary event's fields (without its "e" and "step")."""
    return {k: v for k, v in event.items() if k not in ("e", "step")}


def test_type_differences_names_each_differing_value():
    py = {"a": 1, "b": {"c": 1.0, "d": [1, "x"]}, "e": None, "only": 1}
    cc = {"a": 1.0, "b": {"c": 1.0, "d": [1, 2]}, "e": None}
    assert type_differences(py, cc) == [
        "summary.a: int in python, float in C++", "summary.b.d[1]: str in python, int in C++",
    ]  # fmt: skip


def test_the_summary_keys_are_declared_once():
    """node.summary holds the keys; what rK.json keeps of them (testbed.run.results) is among
    them, and a summary that misses, adds or mistypes one is refused by name."""
    assert set(SUMMARY_KEYS) <= set(summary.KEYS)
    good = {k: (0.0 if float in t else t[0]()) for k, t in summary.FIELDS.items()}
    assert summary.problems(good) == [] and list(summary.ordered(**good)) == list(summary.KEYS)
    with pytest.raises(ValueError, match=r"missing \['robot_impl'\], unknown \['extra'\]"):
        summary.ordered(**{k: v for k, v in good.items() if k != "robot_impl"}, extra=1)
    assert summary.problems(dict(good, frames=True)) == ["frames: bool, not int"]
    assert summary.problems(dict(good, cpu_s=1)) == ["cpu_s: int, not float"]
    assert summary.problems(dict(reversed(good.items()))) == [
        "keys: not in node.summary.KEYS' order"
    ]


def test_key_differences_names_each_missing_key():
    py = {"a": 1, "lateness": {"x": {"n": 1}}, "sent": {"map": 1}}
    cc = {"b": 1, "lateness": {"x": {"m": 1}}, "sent": {"goal": 1, "mop": 1}}
    assert sorted(key_differences(py, cc)) == [
        "summary.a: python only", "summary.b: C++ only", "summary.lateness.x.m: C++ only",
        "summary.lateness.x.n: python only", "summary.sent.mop: not a kind it counts",
    ]  # fmt: skip


@pytest.mark.skipif(unbuilt_reason() is not None, reason=str(unbuilt_reason()))
def test_both_robots_write_the_same_summary_keys(tmp_path):
    py = drive(tmp_path, "python")[3]
    cc = drive(tmp_path, "cpp")[3]
    assert py["robot_impl"] == "python" and cc["robot_impl"] == "cpp"
    assert py["events_failed"] == 0 and cc["events_failed"] == 0
    assert key_differences(py, cc) == []
    assert summary.problems(fields_of(py)) == [] and summary.problems(fields_of(cc)) == []
    assert type_differences(py, cc) == []


def test_a_full_disk_is_counted_and_said_once(caplog):
    """The summary's events_failed: /dev/full refuses every write (ENOSPC), as a full disk."""
    log = EventLog("/dev/full")
    with caplog.at_level(logging.WARNING, logger="node.events"):
        for step in range(3):
            log.write("send", step, kind="map")
    log.close()
    assert log.failed == 3
    assert [r.getMessage() for r in caplog.records if "event log" in r.getMessage()] == [
        "cannot write the event log /dev/full: No space left on device; events are lost "
        "(counted in the summary's events_failed)"
    ]


def run_on_a_full_disk(tmp_path, program: str) -> tuple[int, list[str]]:
    """Run one robot program for a few frames with its event log on /dev/full: its exit
    status and what its log said about the event log (the part after "node.events: ")."""
    path = str(tmp_path / f"{program}-full.sock")
    argv = ["--robot", "r1", "--robots", "1", "--body", path, "--events", "/dev/full",
            "--iface", "lo", "--bind", "127.0.0.1", "--goal-port", str(free_port()),
            "--flood-port", str(free_port()), "--time-scale", "0.02"]  # fmt: skip
    cmd = [str(TB_ROBOT), *argv] if program == "cpp" else [sys.executable, "-m", "node", *argv]
    with socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET) as server:
        server.bind(path)
        server.listen(1)
        env = dict(os.environ, TESTBED_REALTIME="0", PYTHONPATH=REPO)
        proc = subprocess.Popen(cmd, cwd=REPO, env=env, stderr=subprocess.PIPE, text=True)
        try:
            server.settimeout(30)
            conn, _ = server.accept()
            with conn:
                conn.settimeout(30)
                conn.recv(64)  # HELLO
                ranges = np.full(RAYS, np.inf, dtype=np.float32)
                for step in range(5):  # a plan and its events, each one lost
                    conn.send(body.frame(step, 3.0, 4.0, 0.0, ranges, time.monotonic()))
                    conn.recv(64)
                conn.send(body.END)
                _, stderr = proc.communicate(timeout=30)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    said = [ln.split("node.events: ", 1)[1] for ln in stderr.splitlines() if "node.events: " in ln]
    return proc.returncode, said


@pytest.mark.skipif(unbuilt_reason() is not None, reason=str(unbuilt_reason()))
def test_both_robots_say_once_that_their_event_log_is_full(tmp_path):
    expected = [
        "cannot write the event log /dev/full: No space left on device; events are lost "
        "(counted in the summary's events_failed)"
    ]
    assert run_on_a_full_disk(tmp_path, "python") == (0, expected)
    assert run_on_a_full_disk(tmp_path, "cpp") == (0, expected)
