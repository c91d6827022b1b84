"""The report's path pictures (the paper's Figs. 3 and 5), drawn from a run's own records.

Theory of operation. A run writes every robot's position at every step (positions.csv) and
the display's merged map at the end (display/map.npy: unknown, free, occupied cells of
`map_cell` metres, row = y). `paths_figure` draws that map in metres (light grey: what the
display never learnt, which a robot may have seen), each robot's path in
its colour from a hollow square (its start) to a dot (where it finished), its name beside
the dot on the side facing the middle of the map so that it stays inside the frame, and a
scale bar. Without map.npy the paths are drawn on white over the map's size. Long paths
are thinned to at most MAX_POINTS points per robot (the last one always kept).
"""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.artist import Artist
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

from testbed.analysis.plots import plt
from testbed.analysis.runs import FinishedRun
from topology.spec import CELL_M

MAX_POINTS = 2000
_GREYS = np.array([215, 255, 0], dtype=np.uint8)  # unknown, free, occupied


def read_positions(run_dir: Path) -> dict[int, list[tuple[float, float]]]:
    """Robot number -> its (x, y) at every step of positions.csv; {} without the file."""
    path = Path(run_dir) / "positions.csv"
    if not path.is_file():
        return {}
    paths: dict[int, list[tuple[float, float]]] = {}
    with path.open() as f:
        reader = csv.reader(f)
        header = next(reader, [])
        robots = [int(h[1:]) for h in header[1::2]]
        for row in reader:
            for i, k in enumerate(robots):
                x, y = row[1 + 2 * i : 3 + 2 * i]
                if x and y:
                    paths.setdefault(k, []).append((float(x), float(y)))
    return {k: p[:: max(1, len(p) // MAX_POINTS)] + p[-1:] for k, p in paths.items()}


def _extent(run: FinishedRun, shape: tuple[int, int] | None) -> tuple[float, float]:
    """The map's width and height in metres."""
    cell = run.config.extra.get("map_cell") or CELL_M
    if shape is None:
        size = run.config.extra.get("map_size") or [400, 400]
        shape = (size[1], size[0])
    return shape[1] * cell, shape[0] * cell


def _background(ax, run: FinishedRun) -> tuple[float, float, bool]:
    """The display's map in metres; (width, height, whether there was one)."""
    grid = None
    path = run.path / "display" / "map.npy"
    if path.is_file():
        try:
            grid = np.load(path)
        except (OSError, ValueError):
            grid = None
    w, h = _extent(run, grid.shape if grid is not None else None)
    if grid is not None:
        img = _GREYS[np.clip(grid, 0, 2)]
        ax.imshow(img, cmap="gray", vmin=0, vmax=255, extent=(0, w, h, 0),
                  interpolation="nearest")  # fmt: skip
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)  # y grows downwards, as on the map
    return w, h, grid is not None


def _scale_length(width: float) -> float:
    """A round length near a fifth of the width: 1, 2 or 5 times a power of ten."""
    target = width / 5
    base = 10 ** math.floor(math.log10(target))
    return max(m * base for m in (1, 2, 5) if m * base <= target)


def _label(ax, name: str, end: tuple[float, float], size: Sequence[float], colour) -> None:
    """The robot's name beside its last position, on the side facing the map's middle."""
    right, below = end[0] > size[0] / 2, end[1] > size[1] / 2
    ax.annotate(name, end, textcoords="offset points", xytext=(-6 if right else 6,
                6 if below else -6), ha="right" if right else "left",
                va="bottom" if below else "top", fontsize=8, color=colour,
                fontweight="bold", annotation_clip=True)  # fmt: skip


def paths_figure(run: FinishedRun, paths: dict[int, list[tuple[float, float]]]):
    fig, ax = plt.subplots(figsize=(5.5, 5.5))
    *size, has_map = _background(ax, run)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for k, pts in sorted(paths.items()):
        colour = colours[(k - 1) % len(colours)]
        xs, ys = zip(*pts, strict=True)
        ax.plot(xs, ys, color=colour, lw=1.4)
        ax.plot(xs[0], ys[0], marker="s", ms=8, mfc="none", mec=colour, mew=1.8)
        ax.plot(xs[-1], ys[-1], marker="o", ms=6, color=colour)
        _label(ax, f"r{k}", (xs[-1], ys[-1]), size, colour)
    length = _scale_length(size[0])
    bar = AnchoredSizeBar(ax.transData, length, f"{length:g} m", "lower right", pad=0.4,
                          sep=3, frameon=True, size_vertical=size[1] / 150)  # fmt: skip
    ax.add_artist(bar)
    handles: list[Artist]
    handles = [Line2D([], [], marker="s", mfc="none", mec="k", ls="none", label="start"),
               Line2D([], [], marker="o", color="k", ls="none", label="end")]  # fmt: skip
    if has_map:
        handles.append(Patch(facecolor=tuple(_GREYS[[0, 0, 0]] / 255), edgecolor="0.5",
                             label="not in the display's map"))  # fmt: skip
    ax.legend(handles=handles, loc="upper right", fontsize=8, framealpha=0.9)
    c = run.config
    ax.set_title(f"{run.run_id}: {c.robots} robot{'s' if c.robots > 1 else ''}, range "
                 f"{c.comm_range:g} m, {run.steps} steps", fontsize=10)  # fmt: skip
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal")
    fig.tight_layout()
    return fig


def write_paths(run: FinishedRun, stem: Path) -> Path | None:
    """stem.png for the run, or None when it recorded no positions."""
    paths = read_positions(run.path)
    if not paths:
        return None
    png = stem.with_suffix(".png")
    fig = paths_figure(run, paths)
    fig.savefig(png, dpi=110)
    plt.close(fig)
    return png
