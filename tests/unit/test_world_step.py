"""The world's step: motion toward the commanded target, walls, lasers and coverage."""

import numpy as np
import pytest

from node.rays import Laser
from testbed.world.world import World
from testbed.world.worldmap import GroundTruth, empty_terrain, free_space


def make(starts, occ=None, speed=0.1):
    t = empty_terrain(4, 4) if occ is None else GroundTruth(occ)
    return World(t, starts, Laser(1.5, 180), free_space(t, starts), speed, 0.15)


def test_robot_moves_toward_target_by_its_speed_and_stops_there():
    w = make([(1.0, 1.0)])
    w.command(0, (1.25, 1.0))
    w.move()
    assert w.bodies[0].x == pytest.approx(1.1)
    w.move()
    w.move()
    w.move()
    assert (w.bodies[0].x, w.bodies[0].y) == pytest.approx((1.25, 1.0))
    assert w.bodies[0].path_length == pytest.approx(0.25)
    w.command(0, None)
    w.move()
    assert w.bodies[0].x == pytest.approx(1.25)


def test_walls_stop_the_robot():
    w = make([(1.0, 1.0)])
    w.command(0, (-5.0, 1.0))  # through the boundary wall
    for _ in range(20):
        w.move()
    b = w.bodies[0]
    assert b.collisions > 0 and b.y == pytest.approx(1.0)
    assert b.x - 0.15 >= 0.1 - 0.05  # its disc stays off the 10 cm wall (within half a cell)


def test_robot_slides_along_a_wall():
    w = make([(1.0, 1.0)])
    w.command(0, (-5.0, 3.0))  # into the west wall at a slant
    for _ in range(40):
        w.move()
    b = w.bodies[0]
    assert b.x - 0.15 >= 0.1 - 0.05
    assert b.y > 2.0  # it kept going north along the wall


def test_scan_and_coverage():
    w = make([(2.0, 2.0)])
    assert w.coverage() == 0.0
    r = w.scan(0)
    assert r.shape == (180,) and np.isinf(r).all()  # 1.5 m laser in a 4 m room: no walls
    c1 = w.coverage()
    assert 0.3 < c1 < 0.6  # a 1.5 m disc of a 3.8 x 3.8 m room
    w.command(0, (2.0, 3.5))
    for _ in range(5):
        w.move()
        w.scan(0)
    assert w.coverage() > c1
    assert np.isfinite(w.scan(0)).any()  # now the north wall is in range


def walled_world():
    """One robot in an 8 x 8 m terrain with an inner wall: (world, padded obstacle grid)."""
    from node.rays import pad

    t = empty_terrain(8, 8)
    occ = t.occupied.copy()
    occ[60:100, 100:104] = True  # an inner wall
    w = make([(1.0, 1.0)], occ=occ)
    return w, pad(occ, w.laser.pad, True)


def free_poses(w, seed: int, lo: float, hi: float, n: int = 40):
    """Up to n random poses in [lo, hi)^2 off the obstacles; moves robot 1 to each in turn."""
    rng = np.random.default_rng(seed)
    for _ in range(n):
        x, y = rng.uniform(lo, hi, 2)
        if w.truth.occupied[int(y / 0.05), int(x / 0.05)]:
            continue
        w.bodies[0].x, w.bodies[0].y = x, y
        yield x, y


def test_world_scan_equals_the_plain_cast_everywhere():
    w, occp = walled_world()
    for x, y in free_poses(w, seed=2, lo=0.5, hi=7.5):
        assert np.array_equal(w.scan(0), w.laser.cast(occp, x, y))
    assert w.open_space.any() and not w.open_space.all()


def test_open_space_scan_marks_the_marked_samples():
    t = empty_terrain(20, 20)
    w = World(t, [(10.0, 10.0)], Laser(2.0, 360), free_space(t, [(10.0, 10.0)]), 0.1, 0.15)
    for x, y in [(10.0, 10.0), (7.37, 12.91), (13.02, 5.55)]:
        w.bodies[0].x, w.bodies[0].y = x, y
        assert w.open_space[int(y / 0.05), int(x / 0.05)]
        before = w.seen_padded.copy()
        assert np.isinf(w.scan(0)).all()
        expect = before.reshape(-1).copy()
        flat = w.laser.flat_cells(x, y, w.seen_padded.shape[1])
        expect[flat[w.laser.mark]] = True
        assert np.array_equal(w.seen_padded.reshape(-1), expect)


def test_world_marks_seen_as_the_flat_cast_does():
    w, occp = walled_world()
    laser = w.laser
    expect = np.zeros(occp.shape, dtype=bool).reshape(-1)
    for x, y in free_poses(w, seed=4, lo=0.3, hi=7.7):
        w.scan(0)
        flat = laser.flat_cells(x, y, occp.shape[1])
        hit = occp.reshape(-1)[flat]
        n = np.where(hit.any(axis=1), hit.argmax(axis=1), laser.n_samples)
        k = np.arange(laser.n_samples)[None, :]
        expect[flat[laser.mark & (k <= n[:, None])]] = True
        rays = np.flatnonzero(n < laser.n_samples)
        expect[flat[rays, n[rays]]] = True
        assert np.array_equal(w.seen_padded.reshape(-1), expect)


@pytest.mark.parametrize("max_range", [2.0, 1.5])
def test_world_scan_and_seen_equal_the_reference_on_random_poses(max_range):
    """The world's shortcuts (open space, skipped near samples, window tables) change nothing:
    ranges as Laser.cast, seen cells as the flat per-sample marking, on a cluttered map."""
    from node.rays import pad

    t = empty_terrain(12, 12)
    occ = t.occupied.copy()
    rng = np.random.default_rng(9)
    for _ in range(12):  # scattered boxes and thin walls
        r, c = rng.integers(10, 220, 2)
        occ[r : r + rng.integers(1, 30), c : c + rng.integers(1, 4)] = True
    w = World(GroundTruth(occ), [(6.0, 6.0)], Laser(max_range, 360), np.ones_like(occ), 0.1, 0.15)
    laser = w.laser
    occp = pad(occ, laser.pad, True)
    expect = np.zeros(occp.shape, dtype=bool).reshape(-1)
    k = np.arange(laser.n_samples)[None, :]
    done = 0
    while done < 150:
        x, y = (float(v) for v in rng.uniform(0.05, 11.95, 2))
        if occ[int(y / 0.05), int(x / 0.05)]:
            continue
        done += 1
        w.bodies[0].x, w.bodies[0].y = x, y
        assert np.array_equal(w.scan(0), laser.cast(occp, x, y))
        flat = laser.flat_cells(x, y, occp.shape[1])
        hit = occp.reshape(-1)[flat]
        n = np.where(hit.any(axis=1), hit.argmax(axis=1), laser.n_samples)
        expect[flat[laser.mark & (k <= n[:, None])]] = True
        rays = np.flatnonzero(n < laser.n_samples)
        expect[flat[rays, n[rays]]] = True
        assert np.array_equal(w.seen_padded.reshape(-1), expect)


@pytest.mark.parametrize("max_range", [2.0, 1.5, 30.0])
def test_all_scans_in_one_call_equal_one_scan_each(max_range):
    """World.cast_live (a step's casts in one compiled call, with the coverage count it
    keeps) gives each robot's frame World.scan's ranges and pose and marks the same seen
    cells, on a cluttered map, with robots that stay where they were (cached) and dead ones
    (their frames kept as they were); lasers with the tables of scans without hits and one
    too long for them."""
    t = empty_terrain(12, 12)
    occ = t.occupied.copy()
    rng = np.random.default_rng(11)
    for _ in range(12):
        r, c = rng.integers(10, 220, 2)
        occ[r : r + rng.integers(1, 30), c : c + rng.integers(1, 4)] = True
    n = 6

    def world() -> World:
        starts = [(6.0, 6.0)] * n
        return World(GroundTruth(occ), starts, Laser(max_range, 180), ~occ, 0.1, 0.15)

    batch, one = world(), world()
    for step in range(40):
        live = [bool(v) for v in rng.random(n) > 0.15]
        for i in range(n):
            if rng.random() < 0.3 and step:
                continue  # stays where it is: its scan is the cached one
            while True:
                x, y = (float(v) for v in rng.uniform(0.05, 11.95, 2))
                if not occ[int(y / 0.05), int(x / 0.05)]:
                    break
            for w in (batch, one):
                w.bodies[i].x, w.bodies[i].y = x, y
        before = batch.frame_ranges.copy(), batch.frame_has.copy()
        batch.cast_live(np.array(live))
        for i in range(n):
            assert batch.frame_xyt[i].tolist() == [batch.bodies[i].x, batch.bodies[i].y, 0.0]
            if not live[i]:
                assert np.array_equal(batch.frame_ranges[i], before[0][i])
                assert batch.frame_has[i] == before[1][i]
                continue
            got = batch.frame_ranges[i] if batch.frame_has[i] == 1 else np.full(180, np.inf)
            assert np.array_equal(got, one.scan(i))
        assert np.array_equal(batch.seen_padded, one.seen_padded)
        assert batch.coverage() == one.coverage()
        truth = float(np.count_nonzero(batch.seen & ~occ)) / batch.free_total
        assert batch.coverage() == truth
