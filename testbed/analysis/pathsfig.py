"""The report's path pictures (the paper's Figs. 3 and 5), drawn from a run's own records.

Theory of operation. A run writes every robot's position at every step (positions.csv) and
the display's merged map at the end (display/map.npy: unknown, free, occupied cells of
`map_cell` metres, row = y). `paths_figure` draws that map in metres (light grey: what the
display never learnt, which a robot may have seen), each robot's path in
its colour from a hollow square (its start) to a dot (where it finished), its name beside
the dot on the side facing the middle of the map so that it stays inside the frame, and a
scale bar. Without map.npy the paths are drawn on white over the map's size. Long paths
are thinned to at most MAX_POINTS points per robot (the last one always kept).

What a run directory holds is checked, not trusted: positions.csv and map.npy are read
through the one bounded, regular-files-only reader (common.boundedfile); a positions.csv
whose header is not step,x1,y1,... or whose values are not finite coordinates, a map.npy
that is not a 2-D array of whole numbers of at most MAX_MAP_CELLS cells (its header is
checked before anything is allocated), a map_cell or map_size that is not a positive size:
each leaves the picture out (PathsError, one line naming the file and the field; the report
logs it and draws no picture for that run).
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.artist import Artist
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

from common import boundedfile
from testbed.analysis.plots import plt, save_figure
from testbed.analysis.runs import FinishedRun
from testbed.files import csvfiles, layout
from testbed.files.csvfiles import coordinate

MAX_POINTS = 2000
MAX_FILE_BYTES = 256 << 20  # testbed.view.served's limit: a long run's positions.csv
MAX_MAP_CELLS = 1 << 26  # a 64-megacell map: far more than any run's (hundreds a side)
_GREYS = np.array([215, 255, 0], dtype=np.uint8)  # unknown, free, occupied


class PathsError(ValueError):
    """A run's file the paths picture cannot be drawn from; str() is one line naming it."""


def _read(path: Path) -> bytes | None:
    """The file's bytes, None when it is missing; PathsError when it is not readable."""
    try:
        return boundedfile.read(path, MAX_FILE_BYTES)
    except boundedfile.Refused as r:
        if r.kind == "missing":
            return None
        raise PathsError(f"{path}: {boundedfile.describe(r)}") from None


def _columns(path: Path, header: list[str]) -> list[int]:
    try:
        return csvfiles.position_columns(header)
    except ValueError as e:
        raise PathsError(f"{path}: {e}") from None


def read_positions(run_dir: Path) -> dict[int, list[tuple[float, float]]]:
    """Robot number -> its (x, y) at every step of positions.csv; {} without the file;
    PathsError (one line: the file, the line, why) when it is not what runs write."""
    path = Path(run_dir) / csvfiles.POSITIONS_NAME
    data = _read(path)
    if data is None:
        return {}
    paths: dict[int, list[tuple[float, float]]] = {}
    try:
        reader = csv.reader(io.StringIO(data.decode("utf-8"), newline=""))
        robots = _columns(path, next(reader, []))
        for row in reader:
            if len(row) != 1 + 2 * len(robots):
                raise ValueError(f"{len(row)} columns, not {1 + 2 * len(robots)}")
            for i, k in enumerate(robots):
                x, y = row[1 + 2 * i : 3 + 2 * i]
                if x and y:
                    paths.setdefault(k, []).append((coordinate(x), coordinate(y)))
    except (ValueError, csv.Error) as e:  # UnicodeDecodeError is a ValueError
        if isinstance(e, PathsError):
            raise
        line = getattr(locals().get("reader"), "line_num", 0)
        raise PathsError(f"{path} line {line}: {str(e)[:200]}") from None
    return {k: p[:: max(1, len(p) // MAX_POINTS)] + p[-1:] for k, p in paths.items()}


def read_map(path: Path) -> np.ndarray | None:
    """The display's map (a 2-D array of whole numbers), None without the file; its header
    is checked before the array is made (a header may claim 10**12 cells); PathsError
    when it is not one."""
    data = _read(path)
    if data is None:
        return None
    f = io.BytesIO(data)
    try:
        version = np.lib.format.read_magic(f)
        header = {(1, 0): np.lib.format.read_array_header_1_0,
                  (2, 0): np.lib.format.read_array_header_2_0}.get(version)  # fmt: skip
        if header is None:
            raise ValueError(f"format version {version}")
        shape, _, dtype = header(f)
        if len(shape) != 2 or not all(0 < n <= MAX_MAP_CELLS for n in shape):
            raise ValueError(f"shape {shape} is not a 2-D map")
        if shape[0] * shape[1] > MAX_MAP_CELLS or dtype.kind not in "iub":
            raise ValueError(f"{shape[0] * shape[1]} cells of {dtype}: not a map")
        if len(data) - f.tell() != shape[0] * shape[1] * dtype.itemsize:
            raise ValueError("its data is not the size its header says")
        return np.load(io.BytesIO(data), allow_pickle=False)
    except (ValueError, TypeError, OSError, SyntaxError) as e:
        raise PathsError(f"{path}: not a map ({str(e)[:200]})") from None


def _positive(run: FinishedRun, key: str, value, high: float) -> float:
    if (
        isinstance(value, bool)
        or not isinstance(value, int | float)
        or not (math.isfinite(value) and 0 < value <= high)
    ):
        raise PathsError(f"{run.path}: config {key} {str(value)[:40]} is not a size in 0..{high:g}")
    return value


def _extent(run: FinishedRun, shape: tuple[int, int] | None) -> tuple[float, float]:
    """The map's width and height in metres."""
    cell = _positive(run, "map_cell", run.config.map_cell, 1000)
    if shape is None:
        size = run.config.map_size
        if not isinstance(size, list) or len(size) != 2:
            raise PathsError(f"{run.path}: config map_size is not [rows, cols]")
        rows = _positive(run, "map_size", size[1], MAX_MAP_CELLS)
        cols = _positive(run, "map_size", size[0], MAX_MAP_CELLS)
        return cols * cell, rows * cell
    return shape[1] * cell, shape[0] * cell


def _background(ax, run: FinishedRun) -> tuple[float, float, bool]:
    """The display's map in metres; (width, height, whether there was one)."""
    grid = read_map(Path(layout.map_path(run.path)))
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
    try:
        save_figure(fig, png, dpi=110)
    finally:
        plt.close(fig)
    return png
