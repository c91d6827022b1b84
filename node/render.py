"""Pictures of maps and paths (OpenCV): the display's frames and the run's paths picture.

Unknown cells are grey, free white, occupied black; each robot's path is a coloured line
ending in a dot at its last known position. Image row = map row, so y grows downwards.
"""

from __future__ import annotations

import cv2
import numpy as np

from node.grid import FREE, OCC, UNKNOWN

# Distinct BGR colours (tab10), robot k uses COLOURS[(k - 1) % 10].
COLOURS = [
    (180, 119, 31), (14, 127, 255), (44, 160, 44), (40, 39, 214), (189, 103, 148),
    (75, 86, 140), (194, 119, 227), (127, 127, 127), (34, 189, 188), (207, 190, 23),
]  # fmt: skip


# The grey level of each ternary value, indexed by it: unknown grey, free white, occupied black.
_GREY = np.zeros(256, dtype=np.uint8)
_GREY[UNKNOWN], _GREY[FREE], _GREY[OCC] = 170, 255, 0


def map_image(t: np.ndarray, scale: int = 2) -> np.ndarray:
    # A table lookup, then grey to BGR: the display draws a frame every few steps while the
    # robots run, and boolean masks over the three channels cost it twenty times as much.
    img = cv2.cvtColor(cv2.LUT(np.ascontiguousarray(t, dtype=np.uint8), _GREY), cv2.COLOR_GRAY2BGR)
    if scale != 1:
        img = cv2.resize(img, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)
    return img


def draw_paths(
    img: np.ndarray,
    paths: dict[int, list[tuple[float, float]]],
    cell: float,
    scale: int = 2,
    thickness: int = 1,
) -> np.ndarray:
    k = scale / cell
    for robot, pts in sorted(paths.items()):
        if not pts:
            continue
        colour = COLOURS[(robot - 1) % len(COLOURS)]
        a = np.round(np.asarray(pts, dtype=np.float64) * k).astype(np.int32)
        if len(a) > 1:
            cv2.polylines(img, [a.reshape(-1, 1, 2)], False, colour, thickness, cv2.LINE_AA)
        cv2.circle(img, (int(a[-1, 0]), int(a[-1, 1])), max(2, 2 * scale), colour, -1)
        cv2.putText(
            img, f"r{robot}", (int(a[-1, 0]) + 4, int(a[-1, 1]) - 4),
            cv2.FONT_HERSHEY_SIMPLEX, 0.35 * scale, colour, 1, cv2.LINE_AA,
        )  # fmt: skip
    return img


def caption(img: np.ndarray, text: str) -> np.ndarray:
    cv2.putText(img, text, (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 0, 200), 1, cv2.LINE_AA)
    return img


def picture(step: int, t: np.ndarray, paths: dict, cell: float, scale: int) -> np.ndarray:
    """The display's picture of a step: the ternary map `t`, each robot's path so far
    (metres, from its maps), captioned with the step."""
    return caption(draw_paths(map_image(t, scale), paths, cell, scale), f"step {step}")


class Video:
    """An MP4 (mpeg4) video, or MJPG AVI where this OpenCV cannot write MP4."""

    def __init__(self, path_no_ext: str, size: tuple[int, int], fps: float = 10.0):
        self.path = path_no_ext + ".mp4"
        self.w = cv2.VideoWriter(self.path, cv2.VideoWriter.fourcc(*"mp4v"), fps, size)
        if not self.w.isOpened():
            self.path = path_no_ext + ".avi"
            self.w = cv2.VideoWriter(self.path, cv2.VideoWriter.fourcc(*"MJPG"), fps, size)
        self.size = size
        self.frames = 0

    def add(self, img: np.ndarray) -> None:
        if (img.shape[1], img.shape[0]) != self.size:
            img = cv2.resize(img, self.size)
        self.w.write(img)
        self.frames += 1

    def close(self) -> None:
        self.w.release()
