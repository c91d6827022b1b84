"""A live Python robot and a live C++ robot survive a hostile teammate (issue 55): a team of
two on a 10 x 10 m empty map, r1 the Python robot, r2 the C++ robot (build/tb-robot), over
nanomsg. While they explore, a sender in each robot's namespace (so from a teammate's
address) sends the other robot every message of tests.unit.hostile_messages the contract
refuses (400-digit integers, 100,000-deep nesting, BOM, UTF-16, encoded surrogates,
integers past int64, NaN, an empty message, ...) over nanomsg to its goal port.

Both robots must finish and exit 0, the run complete, and each robot's summary (the last
event of robots/rK.events.jsonl, and robots/rK.json where it carries the count) count
exactly those messages as malformed. Before the fix the Python robot ended with status 3 on the
first of them. Skipped where build/tb-robot was not built.
"""

import json
import struct
import subprocess
import sys
import threading
import time
import uuid
from pathlib import Path

import pytest

from node.native import TB_ROBOT, unbuilt_reason
from testbed.run.execute import RunConfig, run
from tests.unit.hostile_messages import REFUSED, ROWS
from topology.kernel import netns
from topology.names import robot_addr, robot_ns
from topology.network import destroy

NOT_BUILT = None if TB_ROBOT.is_file() else (unbuilt_reason() or "build/tb-robot is missing")
pytestmark = pytest.mark.skipif(NOT_BUILT is not None, reason=f"no C++ robot: {NOT_BUILT}")

GOAL_PORT = 5101  # the run's goal port (docs/robot-contract.md, section 3)
HOSTILE = [data for _, data, verdict in ROWS if verdict == REFUSED]

# Run in a robot's namespace: dial the teammate's goal port, send every message of the file
# (u32 length, bytes), exit 0 once all were handed over (nng retries the dial meanwhile).
SENDER = """
import struct, sys, time, pynng
addr, port, path = sys.argv[1:4]
data = open(path, "rb").read()
msgs, i = [], 0
while i < len(data):
    (n,) = struct.unpack_from("!I", data, i)
    msgs.append(data[i + 4 : i + 4 + n])
    i += 4 + n
with pynng.Push0(send_timeout=60000, reconnect_time_min=50, reconnect_time_max=200) as s:
    s.dial(f"tcp://{addr}:{port}", block=False)
    for m in msgs:
        s.send(m)
    time.sleep(1)  # linger: let nng write the last ones out
print(len(msgs))
"""


@pytest.fixture
def ht_name():
    name = "ht" + uuid.uuid4().hex[:6]
    yield name
    destroy(name)


def robot_summary(out: Path, k: int) -> dict:
    """Robot k's summary event (node.events; the C++ robot writes the same)."""
    with open(out / "robots" / f"r{k}.events.jsonl") as f:
        events = [json.loads(line) for line in f]
    return next(e for e in reversed(events) if e["e"] == "summary")


class Senders:
    """One sender per robot, started in its namespace as soon as both namespaces are up."""

    def __init__(self, name: str, messages: Path):
        self.name, self.messages = name, messages
        self.procs: list[subprocess.Popen] = []
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._start, daemon=True)

    def _start(self) -> None:
        wanted = {robot_ns(self.name, k) for k in (1, 2)}
        while not self.stop.is_set() and not wanted <= set(netns.list_names()):
            time.sleep(0.05)
        for k, to in ((1, 2), (2, 1)):  # r1 (Python) sends to r2 (C++), and r2 to r1
            if self.stop.is_set():
                return
            argv = ["ip", "netns", "exec", robot_ns(self.name, k), sys.executable, "-c", SENDER,
                    robot_addr(to), str(GOAL_PORT), str(self.messages)]  # fmt: skip
            self.procs.append(subprocess.Popen(argv, stdout=subprocess.PIPE,
                                               stderr=subprocess.PIPE, text=True))  # fmt: skip

    def finish(self) -> list[tuple[int | None, str, str]]:
        """Stop; (status, stdout, stderr) of each sender, any still running killed."""
        self.stop.set()
        self.thread.join(timeout=10)
        out = []
        for p in self.procs:
            if p.poll() is None:
                p.kill()
            so, se = p.communicate(timeout=10)
            out.append((p.returncode, so, se))
        return out


def test_a_live_python_and_cpp_robot_survive_a_hostile_teammate(tmp_path, ht_name, small_map):
    messages = tmp_path / "hostile.bin"
    messages.write_bytes(b"".join(struct.pack("!I", len(m)) + m for m in HOSTILE))
    out = tmp_path / "run"
    cfg = RunConfig(robots=2, comm_range=20.0, laser_range=2.0, seed=5, time_scale=2.0,
                    max_steps=1500, map=small_map, map_cell=0.1, middleware="nanomsg")  # fmt: skip
    senders = Senders(ht_name, messages)
    senders.thread.start()
    try:
        result = run(cfg, str(out), ht_name, progress=False, cpp_robots=frozenset({2})).to_json()
    finally:
        sent = senders.finish()
    assert [s[:2] for s in sent] == [(0, f"{len(HOSTILE)}\n")] * 2, sent
    assert result["status"] == "complete", result["status_detail"]
    assert result["survivors_finished"]
    for k, impl in ((1, "python"), (2, "cpp")):
        record = json.loads((out / "robots" / f"r{k}.json").read_text())
        assert record["exit_status"] == 0 and not record["crashed"], (k, record["exit_status"])
        summary = robot_summary(out, k)
        assert summary.get("robot_impl", "python") == impl
        assert summary["finished"], f"r{k} did not finish"
        assert summary["malformed"] == len(HOSTILE), (k, summary["malformed"])
        # rK.json carries the summary's keys testbed.run.results.SUMMARY_KEYS names
        assert record.get("malformed", len(HOSTILE)) == len(HOSTILE), (k, record["malformed"])
