"""The display's video frames, kept while the robots run and drawn after: each frame shows the
map and the paths as they were at its step, exactly as a frame drawn at that step would."""

import numpy as np
import pytest

from node.display import Display
from node.grid import FREE, OCC, UNKNOWN


class Frames:
    """Stands in for render.Video: keeps what it is given."""

    def __init__(self):
        self.images: list[np.ndarray] = []
        self.frames = 0

    def add(self, img: np.ndarray) -> None:
        self.images.append(img.copy())
        self.frames += 1


def display(tmp_path, name: str, backlog: int) -> Display:
    d = Display(1, (40, 50), 0.1, None, None, None, str(tmp_path / name), frozenset())
    d.video = Frames()
    d.video_backlog_max = backlog
    return d


def run_steps(d: Display, seed: int) -> list[np.ndarray]:
    """Twenty video frames of a map that fills in and two robots' paths that grow; returns the
    frames drawn at their own step (what the display did before it kept them)."""
    rng = np.random.default_rng(seed)
    at_step = []
    for step in range(0, 200, 10):
        t = np.full((8, 9), UNKNOWN, dtype=np.uint8)
        t[rng.random((8, 9)) < 0.5] = FREE
        t[rng.random((8, 9)) < 0.1] = OCC
        d.grid.merge_ternary(t, int(rng.integers(0, 32)), int(rng.integers(0, 41)))
        for k in (1, 2):
            if rng.random() < 0.7:
                d.paths.setdefault(k, []).append(tuple(rng.uniform(0.0, 4.0, 2)))
        at_step.append(d._frame(step, 1))
        d._keep_video_frame(step)
    while d.video_backlog:
        d._draw_video_frame()
    return at_step


@pytest.mark.parametrize("backlog", [10_000, 3], ids=["kept-to-the-end", "full-backlog"])
def test_frames_kept_for_after_the_run_are_those_of_their_step(tmp_path, backlog):
    d = display(tmp_path, "video", backlog)
    at_step = run_steps(d, seed=4)
    assert d.video.frames == 20
    assert len({img.tobytes() for img in at_step}) == 20  # the frames do differ
    for kept, drawn in zip(d.video.images, at_step, strict=True):
        assert np.array_equal(kept, drawn)
