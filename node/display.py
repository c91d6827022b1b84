"""The display role: a mesh member that does not explore, and shows what reaches it.

Theory of operation. The display sits in its own namespace like a robot (robot N+1 of the
network, with no body: its body link only carries the world's clock). Its inbox receives map
floods and relays them like any robot; message processing merges them into the display's map
and records each robot's position from its floods; every `map_period` steps it floods a small
beacon so that robots notice when it comes back into reach (and send it their whole maps).
With `--maps pubsub` it is given its middleware's map topic instead of the flooder
(node.messaging.maps): it subscribes to the robots' maps and publishes its beacon there.
Visualization renders the merged map with the robots' paths (node.render): a video
frame every `video_every` steps and a PNG snapshot at each chosen step, plus one at the end.
The world sends the display a frame only at the steps it acts on (node.displaysteps), and at
the last step.
A video frame costs some 1.4 ms to draw and encode, against well under 0.1 ms to keep what it
shows (the ternary map and how long each path was), so the frames are kept while the robots
run and drawn and encoded once they have stopped; only a backlog over VIDEO_BACKLOG_BYTES (a
run of many thousand steps) is drawn as it goes, a frame for each frame kept.
"""

from __future__ import annotations

import logging
import os
import select
import threading
import time
from collections import Counter, deque

import cv2
import numpy as np

from common import sched
from node import body, displayreplay, render, wire
from node.displaysteps import VIDEO_EVERY, DisplaySteps
from node.events import EventLog
from node.flood import Flooder
from node.grid import OccupancyGrid
from node.lateness import MS_BOUNDS, Lateness

log = logging.getLogger(__name__)

# The most memory the video frames kept for after the run may take (one byte per cell each).
VIDEO_BACKLOG_BYTES = 64 << 20


class Display:
    def __init__(
        self,
        me: int,
        shape: tuple[int, int],
        cell: float,
        link: body.BodyClient,
        flooder: Flooder,
        events: EventLog,
        out_dir: str,
        snapshots: frozenset[int],
        video_every: int = VIDEO_EVERY,
        scale: int = 2,
        map_period: int = 10,
        time_scale: float = 1.0,
    ):
        self.me = me
        self.shape = shape
        self.cell = cell
        self.link = link
        self.flooder = flooder
        self.events = events
        self.out_dir = out_dir
        self.steps = DisplaySteps(map_period, video_every, snapshots)
        self.scale = scale
        self.grid = OccupancyGrid(shape, cell)
        self.paths: dict[int, list[tuple[float, float]]] = {}
        self.lock = threading.Lock()
        self.stopping = threading.Event()
        self.wake_r, self.wake_w = os.pipe()  # wakes the inbox's select at the end
        self.received: Counter[int] = Counter()
        self.malformed = 0
        self.step = -1
        self.time_scale = time_scale
        # Emulated ms from the world sending a frame to the display done with it (node.lateness).
        self.frame_lateness = Lateness(MS_BOUNDS)
        os.makedirs(out_dir, exist_ok=True)
        size = (shape[1], shape[0])  # video frames at one pixel per cell, snapshots at `scale`
        self.video = render.Video(os.path.join(out_dir, "run"), size)
        # Video frames to draw: (step, ternary map, each robot's path length) at that step.
        self.video_backlog: deque[tuple[int, np.ndarray, dict[int, int]]] = deque()
        self.video_backlog_max = max(16, VIDEO_BACKLOG_BYTES // max(1, shape[0] * shape[1]))

    def run(self) -> None:
        t = threading.Thread(target=self._inbox, name="inbox", daemon=True)
        t.start()
        self.link.ready()
        try:
            # Each frame is handled within two steps or counts as late (the fidelity verdict):
            # real-time priority like the robots' motion control, while the robots run; the
            # video drawn afterwards takes what is left, at normal priority.
            with sched.deadline_priority(*sched.DEADLINE_PRIORITY):
                self._visualization()
        finally:
            self.stopping.set()
            os.write(self.wake_w, b"x")
            t.join(timeout=2.0)
            self._snapshot(self.step, final=True)
            while self.video_backlog:
                self._draw_video_frame()
            self.video.close()
            with self.lock:
                seen = self.grid.ternary()
            counts = {
                "received": {f"r{k}": v for k, v in self.received.items()},
                "malformed": self.malformed, "flood": dict(self.flooder.counts),
                "maps": self.flooder.stats.as_dict(),
                "lateness": {"frame_done_ms": self.frame_lateness.as_dict()},
                "cpu_s": round(time.process_time(), 3),
            }  # fmt: skip
            displayreplay.save_end(self.out_dir, self.events, self.step, seen, self.video, counts)

    def _visualization(self) -> None:
        while not self.stopping.is_set():
            try:
                msg = self.link.recv(timeout=0.5)
            except ValueError as e:  # as the robot's motion control: counted, dropped
                self.malformed += 1
                log.warning("dropped a malformed body message: %s", e)
                continue
            if msg is None:
                continue
            if msg[0] == "end":
                return
            if msg[0] != "frame":
                continue
            step = msg[1].step
            self.step = step
            if self.steps.beacon(step):
                f = msg[1]
                seq = self.flooder.originate(wire.KIND_BEACON, step, wire.pack_beacon(f.x, f.y))
                self.events.write("send", step, kind="beacon", seq=seq)
            if self.steps.video(step) and not self.link.pending():
                self._keep_video_frame(step)
            if msg[1].sent > 0:  # acted on the clock: a snapshot's PNG has no deadline
                late_s = time.monotonic() - msg[1].sent
                self.frame_lateness.add(late_s * 1000 * self.time_scale)
            if self.steps.snapshot(step):
                self._snapshot(step)

    def _frame(self, step: int, scale: int | None = None) -> np.ndarray:
        with self.lock:
            t = self.grid.ternary()
            paths = {k: list(v) for k, v in self.paths.items()}
        return self._picture(step, t, paths, scale or self.scale)

    def _picture(self, step: int, t: np.ndarray, paths, scale: int) -> np.ndarray:
        return render.picture(step, t, paths, self.cell, scale)

    def _keep_video_frame(self, step: int) -> None:
        with self.lock:
            t = self.grid.ternary()
            lengths = {k: len(v) for k, v in self.paths.items()}
        self.video_backlog.append((step, t, lengths))
        if len(self.video_backlog) > self.video_backlog_max:
            self._draw_video_frame()

    def _draw_video_frame(self) -> None:
        """Draw and encode the oldest kept video frame (paths only grow: a prefix is the path
        as it was at that step)."""
        step, t, lengths = self.video_backlog.popleft()
        with self.lock:
            paths = {k: self.paths[k][:n] for k, n in lengths.items()}
        self.video.add(self._picture(step, t, paths, 1))

    def _snapshot(self, step: int, final: bool = False) -> None:
        if step < 0:
            return
        name = displayreplay.snapshot_name(step)
        cv2.imwrite(os.path.join(self.out_dir, name), self._frame(step))
        self.events.write("snapshot", step, file=name, final=final)

    def _inbox(self) -> None:
        while not self.stopping.is_set():
            ready, _, _ = select.select([self.flooder.fileno(), self.wake_r], [], [], 0.5)
            if self.flooder.fileno() not in ready:
                continue
            for h, payload in self.flooder.receive():
                if h.kind == wire.KIND_BEACON:
                    continue  # another display's
                try:
                    if h.kind != wire.KIND_MAP:
                        raise ValueError(f"unexpected flood kind {h.kind}")
                    m = wire.unpack_map(payload, self.shape)
                except ValueError as e:
                    self.malformed += 1
                    log.warning("dropped a malformed flood: %s", e)
                    continue
                with self.lock:
                    self.grid.merge_ternary(m.cells, m.r0, m.c0)
                    self.paths.setdefault(h.origin, []).append((m.x, m.y))
                self.received[h.origin] += 1
                self.events.write("recv", self.step, kind="map", frm=h.origin, sent=h.step)
