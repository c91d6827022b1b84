"""What the C++ display kept while the robots stepped, drawn once they stopped.

Theory of operation. The display's work splits in two. While the robots step it must keep up
with them: relay floods, take the maps, flood its beacon, answer its frames in time. What it
shows (the merged map, the robots' paths, a video frame every few steps, the snapshots) is
drawn only after the run (node.display keeps its video frames for then too). The C++ display
(native/robot/display.cc, `tb-robot --role display`) does the first part and writes a replay
in the display's directory: every map it took, as it came and in the order it merged them,
and the steps at which it kept a video frame or a snapshot; and, when it stops, what it
counted (`stepping.json`). node.nativedisplay starts it and, once it has exited, `finish`
replays the maps into the same grid node.display merges into and draws the same pictures at
the same places in the sequence, then writes map.npy, the final snapshot and the summary
event, as node.display does. The replay's records (little-endian): b"M" u16 origin, u32 length, the
map payload; b"V" u32 step; b"S" u32 step; b"E" once the display stopped in order.
"""

from __future__ import annotations

import json
import os
import resource
import struct
import time
from dataclasses import dataclass

import cv2
import numpy as np

from node import render, wire
from node.events import EventLog
from node.grid import FREE, OccupancyGrid

# The files' names in the display's directory (native/robot/main.cc writes them).
REPLAY_FILE = "replay.bin"
STEPPING_FILE = "stepping.json"
# What stepping.json holds (native/robot/display.cc, Display::stepping_json).
STEPPING_KEYS = ("step", "received", "malformed", "flood", "maps", "lateness")

_MAP = struct.Struct("<HI")
_MARK = struct.Struct("<I")
_MARKS = {b"V": "video", b"S": "snapshot"}


@dataclass(frozen=True)
class Record:
    kind: str  # "map", "video" or "snapshot"
    step: int = -1  # video, snapshot
    origin: int = 0  # map
    payload: bytes = b""  # map


def parse(data: bytes) -> tuple[list[Record], bool]:
    """The records of a replay, and whether it ended in order. ValueError when malformed."""
    out: list[Record] = []
    at = 0
    while at < len(data):
        kind = data[at : at + 1]
        at += 1
        if kind == b"E":
            if at != len(data):
                raise ValueError("replay: bytes after its end")
            return out, True
        try:
            if kind == b"M":
                origin, n = _MAP.unpack_from(data, at)
                at += _MAP.size
                if at + n > len(data):
                    raise ValueError("replay: a map cut short")
                out.append(Record("map", origin=origin, payload=data[at : at + n]))
                at += n
            elif kind in _MARKS:
                (step,) = _MARK.unpack_from(data, at)
                at += _MARK.size
                out.append(Record(_MARKS[kind], step=step))
            else:
                raise ValueError(f"replay: unknown record {kind!r}")
        except struct.error:
            raise ValueError("replay: a record cut short") from None
    return out, False


def encode(records: list[Record], ended: bool = True) -> bytes:
    """The replay of `records` (what native/robot/display.cc writes; for tests)."""
    parts = []
    for r in records:
        if r.kind == "map":
            parts += [b"M", _MAP.pack(r.origin, len(r.payload)), r.payload]
        else:
            parts += [b"V" if r.kind == "video" else b"S", _MARK.pack(r.step)]
    return b"".join(parts) + (b"E" if ended else b"")


def snapshot_name(step: int) -> str:
    return f"step-{step:05d}.png"


def save_end(
    out_dir: str, events: EventLog, step: int, t: np.ndarray, video: render.Video, counts: dict
) -> None:
    """The display's last words (either display): map.npy and the summary event, whose
    fields are `counts` (received, malformed, flood, maps, lateness, cpu_s) and what the
    map and the video say."""
    np.save(os.path.join(out_dir, "map.npy"), t)
    events.write(
        "summary", step, received=counts["received"],
        known_free_cells=int(np.count_nonzero(t == FREE)),
        video=os.path.basename(video.path), video_frames=video.frames,
        malformed=counts["malformed"], flood=counts["flood"], maps=counts["maps"],
        lateness=counts["lateness"], cpu_s=counts["cpu_s"],
    )  # fmt: skip


def finish(
    out_dir: str, shape: tuple[int, int], cell: float, events: EventLog, scale: int = 2
) -> None:
    """Draw what the C++ display kept in `out_dir` and write its last words (node.display's
    end of run); the replay and stepping files go. ValueError when they are unreadable."""
    replay_path = os.path.join(out_dir, REPLAY_FILE)
    stepping_path = os.path.join(out_dir, STEPPING_FILE)
    try:
        with open(stepping_path) as f:
            stepping = json.load(f)
        with open(replay_path, "rb") as f:
            records, ended = parse(f.read())
    except (OSError, json.JSONDecodeError) as e:
        raise ValueError(f"what the display kept is unreadable: {e}") from None
    if not ended:
        raise ValueError(f"{REPLAY_FILE} does not end in order: the display stopped in it")
    if not isinstance(stepping, dict) or any(k not in stepping for k in STEPPING_KEYS):
        raise ValueError(f"{STEPPING_FILE} lacks one of {', '.join(STEPPING_KEYS)}")
    grid = OccupancyGrid(shape, cell)
    paths: dict[int, list[tuple[float, float]]] = {}
    video = render.Video(os.path.join(out_dir, "run"), (shape[1], shape[0]))
    for r in records:
        if r.kind == "map":
            m = wire.unpack_map(r.payload, shape)  # as the display took it: it decodes
            grid.merge_ternary(m.cells, m.r0, m.c0)
            paths.setdefault(r.origin, []).append((m.x, m.y))
        elif r.kind == "video":
            video.add(render.picture(r.step, grid.ternary(), paths, cell, 1))
        else:
            img = render.picture(r.step, grid.ternary(), paths, cell, scale)
            cv2.imwrite(os.path.join(out_dir, snapshot_name(r.step)), img)
    step = int(stepping["step"])
    t = grid.ternary()
    if step >= 0:
        name = snapshot_name(step)
        cv2.imwrite(os.path.join(out_dir, name), render.picture(step, t, paths, cell, scale))
        events.write("snapshot", step, file=name, final=True)
    video.close()
    # The C++ part's CPU (a child that has exited) and this process's.
    cpu = time.process_time()
    child = resource.getrusage(resource.RUSAGE_CHILDREN)
    counts = {k: stepping[k] for k in STEPPING_KEYS[1:]}
    counts["cpu_s"] = round(cpu + child.ru_utime + child.ru_stime, 3)
    save_end(out_dir, events, step, t, video, counts)
    for path in (replay_path, stepping_path):
        os.unlink(path)
