"""Line of sight: walls crossed between robots, and the los range models built on it."""

from pathlib import Path

import numpy as np
import pytest

from topology.radio.los import MapError, Walls, crossings
from topology.radio.ranges import wanted_links

OFFICE = Path(__file__).resolve().parents[2] / "testbed" / "experiments" / "maps" / "office.png"


def walls_with(*columns_m, height=100, width=100, cell=0.1):
    occ = np.zeros((height, width), dtype=bool)
    for x in columns_m:  # vertical walls two cells thick at x metres
        c = round(x / cell)
        occ[:, c : c + 2] = True
    return Walls(occ, cell)


def test_crossings_count_walls_not_cells():
    w = walls_with(3.0, 6.0)
    assert crossings(w, [((1, 5), (2, 5)), ((1, 5), (4, 5)), ((1, 5), (8, 5))]) == [0, 1, 2]
    assert crossings(w, [((1, 1), (8, 9))]) == [2]  # diagonal
    assert crossings(w, [((1, 5), (1, 5))]) == [0]  # same spot
    assert crossings(w, [((-5, 5), (-1, 5))]) == [0]  # off the map is free


def test_los_blocks_or_weakens_and_otherwise_is_the_disc_model():
    w = walls_with(3.0)
    pos = [(1.0, 5.0), (5.0, 5.0), (1.0, 8.0)]
    assert set(wanted_links(pos, 10, "disc")) == {(1, 2), (1, 3), (2, 3)}
    assert set(wanted_links(pos, 10, "los", w)) == {(1, 3)}
    weak = wanted_links(pos, 10, "los", w, wall_loss_pct=30)
    assert weak[(1, 2)].loss_pct == 30 and weak[(1, 3)].loss_pct == 0
    two = wanted_links([(1.0, 5.0), (8.0, 5.0)], 10, "los", walls_with(3.0, 6.0), 30)
    assert two[(1, 2)].loss_pct == 51  # 1 - 0.7 * 0.7
    assert (1, 2) not in wanted_links(pos, 10, "los", w, wall_loss_pct=100)
    assert wanted_links(pos, 10, "los") == wanted_links(pos, 10, "disc")  # no map: no walls
    assert wanted_links(pos, 10, "los-lossy", w)[(1, 3)].loss_pct == 0  # 3 m of 10: no fade


def test_the_shipped_office_map_separates_rooms_and_opens_at_doors():
    w = Walls.from_png(str(OFFICE), 0.05)
    assert w.size_m == (20.0, 20.0)
    room_a, room_b = (2.5, 5.0), (7.5, 5.0)
    corridor_at_door_a, corridor_far = (2.5, 10.0), (12.5, 10.0)
    assert crossings(w, [(room_a, room_b)]) == [1]
    assert crossings(w, [(room_a, corridor_at_door_a)]) == [0]  # through the door
    assert crossings(w, [(corridor_at_door_a, corridor_far)]) == [0]  # along the corridor


def test_bad_map_is_a_clear_error(tmp_path):
    with pytest.raises(MapError, match="does not exist"):
        Walls.from_png(str(tmp_path / "none.png"), 0.05)
    (tmp_path / "x.png").write_text("not a picture")
    with pytest.raises(MapError, match="is not a PNG"):
        Walls.from_png(str(tmp_path / "x.png"), 0.05)


def test_lossy_is_not_a_line_of_sight_model():
    # "lossy" begins with "los": the models are named, not matched by prefix.
    w = walls_with(3.0)
    pos = [(1.0, 5.0), (8.0, 5.0)]
    assert wanted_links(pos, 10, "lossy", w)[(1, 2)].loss_pct > 0  # fades, walls ignored
    assert (1, 2) not in wanted_links(pos, 10, "los-lossy", w)
