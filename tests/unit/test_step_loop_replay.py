"""The compiled step loop and the Python loop (testbed.run.steploop) fed the same commands by
the same scripted team write the same run: positions.csv, coverage.csv, links.csv and
events.jsonl byte for byte, the same bodies (collisions, path lengths, paths to the last bit)
and the same records (answered steps, misses, finishes, stops).

A team's real run is not repeatable (which robot hears what first is real timing), so the
team here is scripted: five robots on threads, each answering every frame at once with a
target that is a function of its number, the step and the pose the frame carries (a frame
out, a command back: the path is fixed by the world's arithmetic alone), over the real body
link (BodyServer, Unix sockets). The network is a stand-in that decides disc links from the
positions at every call (the compiled loop calls it only when its slack is spent). Each
robot says "done" at a step of its own and then answers with a stop; robot 3 is killed at
step 40 (--kill, a real process of its own). No robot can miss a deadline, however loaded
the machine (or slow the sanitized build): each step waits until every robot in the run
has answered the last frames before it begins (a late world changes no path; a late robot
would), and the test checks that none missed one."""

import socket
import subprocess
import threading
from types import SimpleNamespace

import numpy as np
import pytest

from node import body
from node.displaysteps import DisplaySteps
from node.rays import Laser
from testbed.run.files import RunFiles
from testbed.run.record import RobotRecord
from testbed.run.steploop import StepLoop
from testbed.world import stepfast
from testbed.world.bodylink import BodyServer
from testbed.world.world import World
from testbed.world.worldmap import GroundTruth, empty_terrain, free_space

pytestmark = pytest.mark.skipif(not stepfast.AVAILABLE, reason="the step core is not built")

N = 5
RANGE_M = 5.0
KILLED, KILL_STEP = 3, 40


def terrain() -> GroundTruth:
    t = empty_terrain(10, 10)
    occ = t.occupied.copy()
    occ[60:140, 100:104] = True  # a wall to slide along and bump into
    occ[40:44, 20:90] = True
    return GroundTruth(occ)


def target(k: int, step: int, x: float, y: float) -> tuple[float, float]:
    """Robot k's target on the frame of `step` at (x, y): a corner of the map, changing every
    25 steps, nudged by where it stands (so the path feeds back into the commands)."""
    corners = [(1.0, 1.0), (9.0, 1.5), (8.5, 9.0), (1.5, 8.0), (5.0, 5.0)]
    cx, cy = corners[(k + step // 25) % len(corners)]
    return (cx + 0.1 * (y % 1.0), cy - 0.1 * (x % 1.0))


class Answers:
    """The last frame each scripted robot answered, for the step loop to wait on."""

    def __init__(self) -> None:
        self.last = dict.fromkeys(range(1, N + 1), -1)
        self.cond = threading.Condition()

    def answered(self, k: int, step: int) -> None:
        with self.cond:
            self.last[k] = step
            self.cond.notify_all()

    def wait(self, step: int, live: np.ndarray) -> bool:
        """Until every robot still in the run (live[k - 1]) answered `step`'s frame."""
        with self.cond:
            return self.cond.wait_for(
                lambda: all(self.last[k] >= step for k in self.last if live[k - 1]), 60.0
            )


def robot(path: str, k: int, done_at: int, answers: Answers) -> None:
    c = body.BodyClient(path, k)
    c.ready()
    try:
        while True:
            msg = c.recv(30.0)
            if msg is None or msg[0] == "end":
                return
            if msg[0] != "frame":
                continue
            f = msg[1]
            if f.step == done_at:
                c.send(body.done(f.step))
            stop = f.step >= done_at
            c.send(body.cmd(f.step, None if stop else target(k, f.step, f.x, f.y)))
            answers.answered(k, f.step)
    finally:
        c.close()


class Stub:
    """A fork server and its child as StepLoop looks at them: nothing ever exits unasked."""

    def __init__(self, pid: int) -> None:
        self.ctl_pair = socket.socketpair()
        self.ctl = self.ctl_pair[0]
        self.server = self
        self.pid = pid
        self.returncode = None

    def collect(self, timeout: float) -> None:
        return None


class DiscNet:
    """The topology controller's part StepLoop calls: disc links among the robots."""

    def __init__(self) -> None:
        self.isolated: frozenset = frozenset()
        self.current: dict = {}
        self.spec = SimpleNamespace(range_model="disc", medium="veth", comm_range=RANGE_M)
        self.persistent = False
        self.calls = 0

    def set_positions(self, positions):
        self.calls += 1
        xy = np.asarray(positions[:-1], dtype=np.float64)  # the last: the display's
        d = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))
        want = {(i + 1, j + 1) for i in range(len(xy)) for j in range(i + 1, len(xy))
                if d[i, j] <= RANGE_M}  # fmt: skip
        added, removed = want - set(self.current), set(self.current) - want
        self.current = dict.fromkeys(want)
        return sorted(added), sorted(removed)


def replay(tmp_path, loop: str, monkeypatch) -> tuple[dict, dict, int]:
    monkeypatch.setenv("TESTBED_STEP_LOOP", loop)
    out = tmp_path / loop
    out.mkdir()
    truth = terrain()
    starts = [(1.0 + 0.6 * i, 2.0) for i in range(N)]
    world = World(truth, starts, Laser(2.0, 180), free_space(truth, starts), 0.1, 0.15)
    server = BodyServer(str(out / "body.sock"))
    sleeper = subprocess.Popen(["sleep", "60"])
    answers = Answers()
    threads = [threading.Thread(target=robot, args=(server.path, k, 120 + 15 * k, answers),
                                daemon=True)
               for k in range(1, N + 1)]  # fmt: skip
    for t in threads:
        t.start()
    stubs = {k: Stub(sleeper.pid if k == KILLED else 0) for k in range(1, N + 1)}
    try:
        server.wait_for(set(range(1, N + 1)), set(), timeout=10.0)
        robots = {k: RobotRecord(k, proc=stubs[k]) for k in range(1, N + 1)}  # type: ignore[arg-type]
        cfg = SimpleNamespace(kills=[(KILLED, KILL_STEP)], max_steps=1000, time_scale=50.0,
                              isolate=[])  # fmt: skip
        prep = SimpleNamespace(world=world, cfg=cfg, display_steps=DisplaySteps(10),
                               display_pos=(5.0, 5.0), display_k=N + 1)  # fmt: skip
        with RunFiles(str(out), N) as files:
            net = DiscNet()
            started = SimpleNamespace(net=net, server=server, files=files, live=None)
            loop_ = StepLoop(prep, started, robots, False)  # type: ignore[arg-type]
            step = loop_.step

            def answered_then_step():
                assert answers.wait(loop_.clock.step, loop_.live_robots), "a robot hung"
                return step()

            loop_.step = answered_then_step  # type: ignore[method-assign]
            assert loop_.kind == loop
            status = loop_.run()
    finally:
        server.close()
        for t in threads:
            t.join(10.0)
        sleeper.kill()
        sleeper.wait()
        for s in stubs.values():
            for sock in s.ctl_pair:
                sock.close()
    summary = loop_.clock.summary()
    texts = {}
    for name in ("positions.csv", "coverage.csv", "links.csv", "events.jsonl"):
        with open(out / name) as f:
            texts[name] = f.read()
    a = world.body_arrays
    state = {
        "status": status, "missed": summary.missed_robots, "steps": summary.steps,
        "records": [(r.last_cmd, r.finish_step, r.missed, r.missed_steps, r.stopped_step)
                    for r in robots.values()],
        "bodies": (a.xyt.tobytes(), a.collisions.tolist(), a.path_length.tobytes(), world.paths),
    }  # fmt: skip
    return texts, state, net.calls


@pytest.mark.slow
def test_both_loops_write_the_same_run_from_the_same_commands(tmp_path, monkeypatch):
    runs = {loop: replay(tmp_path, loop, monkeypatch) for loop in ("python", "compiled")}
    assert all(state["missed"] == 0 for _, state, _ in runs.values())
    (pt, ps, p_calls), (ct, cs, c_calls) = runs["python"], runs["compiled"]
    # The Python loop gives the controller the positions every step; the compiled one only
    # when a link may have come or gone (its slack), and the links are the same.
    assert p_calls == ps["steps"] and 0 < c_calls < p_calls, (p_calls, c_calls)
    assert ps["status"][0] == "complete" and ps["steps"] > 150
    assert any(ps["bodies"][1]) and "remove" in pt["links.csv"] and "stopped" in pt["events.jsonl"]
    for name in pt:
        assert pt[name] == ct[name], name
    assert ps == cs
