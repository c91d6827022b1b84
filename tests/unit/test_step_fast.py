"""The world's compiled step (native/stepcore/worldstep.cc through testbed.world.stepfast)
against its Python twins: math.hypot and math.atan2 bit for bit, World.move on random maps,
bodies and targets (the same poses, collisions, path lengths and paths, to the last bit), the
commands and deadline count of StepLoop._take_commands and _collect_commands over real
sockets, the look at the fork servers, and the deadline's sleep."""

import math
import os
import socket
import struct
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from node import body
from node.rays import Laser
from testbed.files.resultfile import MAX_MISSED_STEPS_KEPT
from testbed.run.record import RobotRecord
from testbed.world import stepfast
from testbed.world.bodylink import BodyServer
from testbed.world.world import World
from testbed.world.worldmap import GroundTruth, empty_terrain, free_space

pytestmark = pytest.mark.skipif(not stepfast.AVAILABLE, reason="the step core is not built")


def same(a: float, b: float) -> bool:
    """Bit for bit (NaN as NaN)."""
    return struct.pack("<d", a) == struct.pack("<d", b)


any_float = st.floats(allow_nan=True, allow_infinity=True, allow_subnormal=True)


@settings(max_examples=3000, deadline=None)
@given(any_float, any_float)
def test_hypot_and_atan2_are_cpythons(x, y):
    assert stepfast.lib is not None
    assert same(stepfast.lib.sc_py_hypot(x, y), math.hypot(x, y))
    assert same(stepfast.lib.sc_py_atan2(y, x), math.atan2(y, x))


def test_hypot_and_atan2_on_a_million_distances():
    """The magnitudes World.move meets (a step's moves, a map's distances), and subnormals."""
    assert stepfast.lib is not None
    rng = np.random.default_rng(5)
    for scale in (1e-9, 1e-3, 0.1, 1.0, 30.0, 3e38, 1e-310):
        a = (rng.uniform(-1, 1, 50_000) * scale).tolist()
        b = (rng.uniform(-1, 1, 50_000) * scale * rng.choice([1, 1e-3, 1e-12], 50_000)).tolist()
        for x, y in zip(a, b, strict=True):
            assert stepfast.lib.sc_py_hypot(x, y) == math.hypot(x, y), (x, y)
            assert stepfast.lib.sc_py_atan2(y, x) == math.atan2(y, x), (x, y)


def cluttered(seed: int, side_m: float = 8.0) -> GroundTruth:
    t = empty_terrain(side_m, side_m)
    occ = t.occupied.copy()
    rng = np.random.default_rng(seed)
    cells = occ.shape[0]
    for _ in range(10):  # boxes and thin walls, for slides and collisions
        r, c = rng.integers(4, cells - 20, 2)
        occ[r : r + rng.integers(1, 20), c : c + rng.integers(1, 5)] = True
    return GroundTruth(occ)


def twin_worlds(truth: GroundTruth, starts, speed: float):
    def make() -> World:
        return World(truth, starts, Laser(1.5, 90), free_space(truth, starts), speed, 0.15)

    return make(), make()


def free_starts(truth: GroundTruth, rng, n: int) -> list[tuple[float, float]]:
    out: list[tuple[float, float]] = []
    blocked = truth.inflated(0.15)
    side = truth.shape[0] * truth.cell
    while len(out) < n:
        x, y = (round(float(v), 3) for v in rng.uniform(0.2, side - 0.2, 2))
        if not blocked[int(y / truth.cell), int(x / truth.cell)]:
            out.append((x, y))
    return out


def assert_same_bodies(py: World, c: World) -> None:
    a, b = py.body_arrays, c.body_arrays
    assert a.xyt.tobytes() == b.xyt.tobytes()
    assert a.collisions.tolist() == b.collisions.tolist()
    assert a.path_length.tobytes() == b.path_length.tobytes()
    assert py.paths == c.paths
    assert py.step_no == c.step_no


def targets_for(rng, world: World, step: int) -> list:
    """Each robot's command this step: a target near it, on an axis, far, on itself, off the
    map, as float32 on the wire; or none (stop); or unchanged (no command)."""
    out: list[str | tuple[float, float] | None] = []
    for b in world.bodies:
        kind = rng.integers(0, 9)
        if kind == 0:
            out.append("keep")
        elif kind == 1:
            out.append(None)
        elif kind == 2:
            out.append((b.x, b.y))  # where it stands (as float32: a hair off)
        elif kind == 3:
            out.append((b.x + float(rng.uniform(-3, 3)), b.y))  # along an axis
        elif kind == 4:
            out.append((float(rng.uniform(-5, 15)), float(rng.uniform(-5, 15))))  # maybe off
        elif kind == 5:
            out.append((b.x + float(rng.uniform(-1e-6, 1e-6)), b.y))  # a step shorter than 1e-9?
        else:
            out.append((b.x + float(rng.uniform(-2, 2)), b.y + float(rng.uniform(-2, 2))))
    return [t if isinstance(t, str) or t is None else tuple(float(np.float32(v)) for v in t)
            for t in out]  # fmt: skip


@pytest.mark.parametrize("seed", range(8))
def test_compiled_move_equals_world_move(seed):
    rng = np.random.default_rng(seed)
    truth = cluttered(seed)
    n = int(rng.integers(1, 9))
    speed = float(rng.choice([0.1, 0.05, 0.37, 1.0]))
    py, c = twin_worlds(truth, free_starts(truth, rng, n), speed)
    live = np.ones(n, dtype=bool)
    fast = stepfast.WorldStep(c, live)
    for step in range(300):
        for i, t in enumerate(targets_for(rng, py, step) if step % 7 == 0 else ["keep"] * n):
            if t != "keep":
                py.command(i, t)
                c.command(i, t)
        if rng.random() < 0.02:  # a robot stops for good (killed, crashed)
            i = int(rng.integers(0, n))
            py.bodies[i].alive = c.bodies[i].alive = False
        py.move()
        assert fast.move()
        assert_same_bodies(py, c)


def test_a_target_that_is_not_finite_moves_no_one_in_either_move():
    """A robot's command may carry any float32 (node.body): a target no way leads to leaves
    its robot where it is, no collision counted, in World.move (it ended the world's step
    loop with a ValueError before) and in the compiled move alike; the others move on."""
    truth = empty_terrain(4, 4)
    starts = [(1.0, 1.0), (2.0, 2.0), (3.0, 1.0)]
    py, c = twin_worlds(truth, starts, 0.1)
    fast = stepfast.WorldStep(c, np.ones(3, dtype=bool))
    for target in ((math.inf, 2.0), (2.0, -math.inf), (math.nan, 2.0), (3.4e38, -3.4e38)):
        for w in (py, c):
            w.command(0, (3.0, 1.0))
            w.command(1, target)
            w.command(2, (1.0, 3.0))
        py.move()
        assert fast.move()
        assert_same_bodies(py, c)
    assert py.body_arrays.xyt[1, :2].tolist() != [2.0, 2.0]  # the huge finite one drove
    assert py.body_arrays.collisions.tolist() == c.body_arrays.collisions.tolist()


def test_compiled_move_leaves_a_position_that_is_not_finite_to_world_move():
    truth = empty_terrain(4, 4)
    py, c = twin_worlds(truth, [(1.0, 1.0)], 0.1)
    fast = stepfast.WorldStep(c, np.ones(1, dtype=bool))
    c.command(0, (3.0, 1.0))
    c.bodies[0].x = math.nan  # the world never puts a robot there; were it to, Python decides
    before = c.body_arrays.xyt.tobytes()
    assert not fast.move()
    assert c.body_arrays.xyt.tobytes() == before and c.step_no == 0
    c.bodies[0].alive = False  # a dead robot is not looked at
    assert fast.move()


def test_compiled_move_log_drains_into_the_paths_when_full():
    truth = empty_terrain(20, 20)
    py, c = twin_worlds(truth, [(1.0, 1.0)], 0.01)
    fast = stepfast.WorldStep(c, np.ones(1, dtype=bool))
    for w in (py, c):
        w.command(0, (19.0, 1.0))
    for _ in range(3 * len(c.move_log.i)):
        py.move()
        assert fast.move()
    assert_same_bodies(py, c)


class Team:
    """A body server with robots 1..n connected (and a display), the robots' records and a
    world: what StepLoop's take works on."""

    def __init__(self, tmp_path, n: int, tag: str) -> None:
        self.server = BodyServer(str(tmp_path / f"{tag}.sock"))
        self.clients = [body.BodyClient(self.server.path, k) for k in range(1, n + 1)]
        self.clients.append(body.BodyClient(self.server.path, n + 1, body.ROLE_DISPLAY))
        for cl in self.clients:
            cl.ready()
        self.server.wait_for(set(range(1, n + 1)), {n + 1}, timeout=5.0)
        truth = empty_terrain(6, 6)
        starts = [(1.0 + 0.5 * i, 1.0) for i in range(n)]
        self.world = World(truth, starts, Laser(1.5, 90), free_space(truth, starts), 0.1, 0.15)
        self.robots = {k: RobotRecord(k) for k in range(1, n + 1)}

    def close(self) -> None:
        for cl in self.clients:
            cl.close()
        self.server.close()


def python_take(team: Team, step: int, live: np.ndarray) -> int:
    """StepLoop._take_commands and the deadline count of _collect_commands, as written."""
    for k, msg in team.server.take(len(team.robots)):
        if not 1 <= k <= len(team.robots):
            continue
        r = team.robots[k]
        if msg[0] == "cmd":
            r.answered(msg[1])
            team.world.command(k - 1, msg[2])
        elif msg[0] == "done":
            r.finished(step, msg[1])
    missed = 0
    for k, r in team.robots.items():
        if not live[k - 1]:
            continue  # a robot out of the run (RobotRecord.gone) is never counted
        if r.missed_deadline(step):
            missed += 1
    return missed


def send(client, data: bytes) -> None:
    client.sock.send(data)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 6))
def test_compiled_take_equals_the_python_take(tmp_path_factory, seed, n):
    """The same datagrams to two teams: one taken as StepLoop takes them in Python, the other
    by the compiled take; the same targets, answered steps, finishes and misses."""
    tmp = tmp_path_factory.mktemp("take")
    rng = np.random.default_rng(seed)
    a, b = Team(tmp, n, "a"), Team(tmp, n, "b")
    try:
        live = np.ones(n, dtype=bool)
        fast = stepfast.WorldStep(b.world, live)
        fast.load_records(b.robots)
        for step in range(1, 40):
            if rng.random() < 0.05:
                live[int(rng.integers(0, n))] = False
            for k in range(1, n + 2):  # the display's commands are not taken
                for _ in range(int(rng.integers(0, 4))):
                    go = bool(rng.random() < 0.8)
                    xy = (float(rng.uniform(-9, 9)), float(rng.uniform(-9, 9)))
                    s = int(rng.integers(max(0, step - 3), step + 2))
                    roll = rng.random()
                    if roll < 0.08:
                        data = body.done(s)
                    elif roll < 0.1:
                        data = b"Cbad"  # malformed: counted, not taken
                    else:
                        data = body.cmd(s, xy if go else None)
                    send(a.clients[k - 1], data)
                    send(b.clients[k - 1], data)
            missed_a = python_take(a, step, live)
            socks = b.server.step_sockets(n)
            fast.sockets(socks)
            used, hung, missed_b, _ = fast.take(step, True)
            for k, msg in b.server.taken_rest(socks, used, hung):
                if 1 <= k <= n and msg[0] == "done":
                    b.robots[k].finished(step, msg[1])
            assert missed_a == missed_b
            assert a.world.body_arrays.target.tobytes() == b.world.body_arrays.target.tobytes()
            assert (
                a.world.body_arrays.has_target.tolist() == b.world.body_arrays.has_target.tolist()
            )
        fast.store_records(b.robots)
        assert [vars(r) for r in a.robots.values()] == [vars(r) for r in b.robots.values()]
        assert a.server.malformed == b.server.malformed
    finally:
        a.close()
        b.close()


def test_missed_steps_are_kept_up_to_the_cap_and_stored_back():
    truth = empty_terrain(4, 4)
    w = World(truth, [(1.0, 1.0)], Laser(1.5, 90), free_space(truth, [(1.0, 1.0)]), 0.1, 0.15)
    live = np.ones(1, dtype=bool)
    fast = stepfast.WorldStep(w, live)
    r = RobotRecord(1, last_cmd=4, missed=2, missed_steps=[2, 3])
    fast.load_records({1: r})
    fast.sockets(_NoSockets())
    for step in range(5, 5 + MAX_MISSED_STEPS_KEPT + 10):
        assert fast.take(step, True)[2] == 1
    assert fast.take(3, True)[2] == 0  # answered
    assert fast.take(10**6, False)[2] == 0  # not counted
    live[0] = False
    assert fast.take(10**6, True)[2] == 0  # out of the run
    fast.store_records({1: r})
    assert r.missed == 2 + MAX_MISSED_STEPS_KEPT + 10
    assert r.missed_steps == [2, 3] + list(range(5, 5 + MAX_MISSED_STEPS_KEPT - 2))
    assert r.last_cmd == 4


class _NoSockets:
    """No body link at all (a team whose sockets all went)."""

    fds = np.full(1, -1, dtype=np.int32)
    fds_p = fds.ctypes.data
    taken = np.zeros(1, dtype=np.int32)
    steps = np.zeros(1, dtype=np.int64)
    go = np.zeros(1, dtype=np.uint8)
    xy = np.zeros((1, 2), dtype=np.float64)
    hung = np.zeros(1, dtype=np.uint8)
    others = np.zeros(1 << 17, dtype=np.uint8)
    counts = np.zeros(2, dtype=np.int32)


def test_take_says_when_a_watched_descriptor_has_something():
    truth = empty_terrain(4, 4)
    w = World(truth, [(1.0, 1.0)], Laser(1.5, 90), free_space(truth, [(1.0, 1.0)]), 0.1, 0.15)
    fast = stepfast.WorldStep(w, np.ones(1, dtype=bool))
    fast.sockets(_NoSockets())
    a, b = socket.socketpair()
    try:
        fast.watch([a.fileno()])
        assert fast.take(1, False)[3] is False
        b.send(b'{"exit": 1, "status": 0}\n')
        assert fast.take(1, False)[3] is True
        a.recv(100)
        assert fast.take(1, False)[3] is False
        b.close()  # the fork server died: Python must look
        assert fast.take(1, False)[3] is True
    finally:
        a.close()
        b.close()
    fast.watch([])
    assert fast.take(1, False)[3] is False


def test_sleep_until_the_deadline():
    fast = stepfast.WorldStep(World(empty_terrain(4, 4), [(1.0, 1.0)], Laser(1.5, 90),
                                    free_space(empty_terrain(4, 4), [(1.0, 1.0)]), 0.1, 0.15),
                              np.ones(1, dtype=bool))  # fmt: skip
    for wait in (0.0, 0.003, 0.02):
        deadline = time.monotonic() + wait
        now = fast.sleep_until(deadline)
        assert deadline <= now <= time.monotonic() < deadline + 0.05
    past = time.monotonic() - 1.0
    assert fast.sleep_until(past) - time.monotonic() < 0.001
    for odd in (math.nan, math.inf, -math.inf, 1e300):
        assert abs(fast.sleep_until(odd) - time.monotonic()) < 0.01  # at once, never for ever
    assert os.environ.get("TESTBED_STEP_LOOP", "") in ("", "compiled", "python")
