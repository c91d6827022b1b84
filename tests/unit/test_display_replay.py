"""What the C++ display keeps while the robots step is drawn after (node.displayreplay): the
same map, pictures and summary as the Python display (node.display) makes of the same maps,
frames and snapshots in the same order."""

import json
import os

import cv2
import numpy as np
import pytest

from node import displayreplay, render, wire
from node.display import Display
from node.displayreplay import Record
from node.events import EventLog
from node.grid import FREE, OCC, UNKNOWN

SHAPE, CELL = (40, 50), 0.1


class Frames:
    """Stands in for render.Video: keeps what it is given."""

    def __init__(self, path_no_ext: str = "run", size=None):
        self.path = path_no_ext + ".mp4"
        self.images: list[np.ndarray] = []
        self.frames = 0

    def add(self, img: np.ndarray) -> None:
        self.images.append(img.copy())
        self.frames += 1

    def close(self) -> None:
        pass


def sequence(seed: int) -> list[Record]:
    """Maps from two robots that fill in, a video frame every tenth step, two snapshots."""
    rng = np.random.default_rng(seed)
    out = []
    for step in range(0, 200, 10):
        for k in (1, 2):
            if rng.random() < 0.7:
                t = np.full((8, 9), UNKNOWN, dtype=np.uint8)
                t[rng.random((8, 9)) < 0.5] = FREE
                t[rng.random((8, 9)) < 0.1] = OCC
                x, y = rng.uniform(0.0, 4.0, 2)
                payload = wire.pack_map(x, y, t, int(rng.integers(0, 32)), int(rng.integers(0, 41)))
                out.append(Record("map", origin=k, payload=payload))
        out.append(Record("video", step=step))
        if step in (50, 120):
            out.append(Record("snapshot", step=step))
    return out


STEPPING = {
    "step": 195, "received": {"r1": 14, "r2": 13}, "malformed": 1,
    "flood": {"duplicate": 3}, "maps": {"transport": "flood", "received": 27},
    "lateness": {"frame_done_ms": {"n": 20, "late": 20, "max": 1.5, "hist": {}}},
}  # fmt: skip


def reference(tmp_path, records: list[Record]):
    """What node.display makes of the same sequence: its video frames, its snapshots' images
    and its grid."""
    d = Display(3, SHAPE, CELL, None, None, None, str(tmp_path / "python"), frozenset())
    d.video = Frames()
    snapshots = {}
    for r in records:
        if r.kind == "map":
            m = wire.unpack_map(r.payload, SHAPE)
            d.grid.merge_ternary(m.cells, m.r0, m.c0)
            d.paths.setdefault(r.origin, []).append((m.x, m.y))
        elif r.kind == "video":
            d._keep_video_frame(r.step)
        else:
            snapshots[r.step] = d._frame(r.step)
    snapshots[STEPPING["step"]] = d._frame(STEPPING["step"])
    while d.video_backlog:
        d._draw_video_frame()
    return d.video.images, snapshots, d.grid.ternary()


def test_the_replay_is_drawn_as_the_python_display_draws(tmp_path, monkeypatch):
    records = sequence(seed=5)
    out = tmp_path / "cpp"
    out.mkdir()
    (out / displayreplay.REPLAY_FILE).write_bytes(displayreplay.encode(records))
    (out / displayreplay.STEPPING_FILE).write_text(json.dumps(STEPPING))
    videos = []
    monkeypatch.setattr(render, "Video", lambda *a: videos.append(Frames(*a)) or videos[-1])
    events = EventLog(str(out / "events.jsonl"))
    displayreplay.finish(str(out), SHAPE, CELL, events)
    events.close()
    frames, snapshots, grid = reference(tmp_path, records)
    assert len(videos[0].images) == len(frames) == 20
    for mine, theirs in zip(videos[0].images, frames, strict=True):
        assert np.array_equal(mine, theirs)
    for step, img in snapshots.items():
        png = cv2.imread(str(out / f"step-{step:05d}.png"))
        assert png is not None and np.array_equal(png, img), step
    assert np.array_equal(np.load(out / "map.npy"), grid)
    lines = [json.loads(x) for x in (out / "events.jsonl").read_text().splitlines()]
    assert lines[0] == {"e": "snapshot", "step": 195, "file": "step-00195.png", "final": True}
    summary = lines[1]
    assert summary["known_free_cells"] == int(np.count_nonzero(grid == FREE))
    assert summary["video"] == "run.mp4" and summary["video_frames"] == 20
    for k in displayreplay.STEPPING_KEYS[1:]:
        assert summary[k] == STEPPING[k]
    assert summary["cpu_s"] >= 0
    assert sorted(os.listdir(out)) == sorted(
        ["events.jsonl", "map.npy"] + [f"step-{s:05d}.png" for s in snapshots]
    )


def test_a_replay_parses_back_and_says_whether_it_ended_in_order():
    records = sequence(seed=1)
    assert displayreplay.parse(displayreplay.encode(records)) == (records, True)
    assert displayreplay.parse(displayreplay.encode(records, ended=False)) == (records, False)


@pytest.mark.parametrize(
    "data",
    [b"M\x01\x00\x10\x00\x00\x00abc", b"V\x01\x00", b"Q", b"E trailing", b"M\x01"],
    ids=["map-cut-short", "mark-cut-short", "unknown", "after-end", "header-cut-short"],
)
def test_a_malformed_replay_is_refused(data):
    with pytest.raises(ValueError, match="replay"):
        displayreplay.parse(data)


def test_what_the_display_kept_must_be_whole(tmp_path):
    (tmp_path / displayreplay.REPLAY_FILE).write_bytes(b"E")
    (tmp_path / displayreplay.STEPPING_FILE).write_text('{"step": 3}')
    with pytest.raises(ValueError, match="lacks"):
        displayreplay.finish(str(tmp_path), SHAPE, CELL, EventLog(None))
    (tmp_path / displayreplay.STEPPING_FILE).write_text(json.dumps(STEPPING))
    (tmp_path / displayreplay.REPLAY_FILE).write_bytes(b"V\x01\x00\x00\x00")
    with pytest.raises(ValueError, match="does not end in order"):
        displayreplay.finish(str(tmp_path), SHAPE, CELL, EventLog(None))
    os.unlink(tmp_path / displayreplay.STEPPING_FILE)
    with pytest.raises(ValueError, match="unreadable"):
        displayreplay.finish(str(tmp_path), SHAPE, CELL, EventLog(None))
