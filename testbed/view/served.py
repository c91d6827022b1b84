"""What `testbed view` may read and serve of a run directory: the run's own files, nothing else.

A results directory may come from someone else, and the view runs as whoever starts it
(often root), so what the directory says is not trusted:

- a file is read only if its real path (every symlink followed) lies inside the run
  directory, it is a regular file (no FIFO, device or directory) and it is at most
  MAX_FILE_BYTES long;
- a picture (the map, the display's snapshots) is served only if it is such a file and a
  PNG (its signature and header), and the map also when it is one of the maps the testbed
  ships (testbed/experiments/maps), where sweeps name it; a map that config.json names
  anywhere else is not served (the page then draws no picture) and the view says so;
- nothing a request names reaches the file system: pictures are looked up by what the run
  wrote (config.json's map, display/step-NNNNN.png for the steps that exist).
"""

from __future__ import annotations

import os
import stat
import struct
from pathlib import Path

from testbed import PACKAGE_DIR
from testbed.files import layout

PACKAGED_MAPS = PACKAGE_DIR / "experiments" / "maps"
# The largest file the view reads or serves: a 50-robot run of 100000 steps writes a
# positions.csv of about 70 MB; the parsed numbers take about five times as much memory.
MAX_FILE_BYTES = 256 << 20
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
RUN_MAP = "map.png"  # the copy of its map a run keeps in its directory


def _under(path: Path, root: Path) -> bool:
    return path == root or root in path.parents


def regular_file(path: Path, roots: tuple[Path, ...]) -> Path | None:
    """The real path of `path` if it lies under one of `roots` (real paths) and is a
    regular file of at most MAX_FILE_BYTES, else None."""
    try:
        real = Path(os.path.realpath(path))
        st = os.stat(real)
    except (OSError, ValueError):  # ValueError: a NUL in the name
        return None
    if not any(_under(real, root) for root in roots):
        return None
    if not stat.S_ISREG(st.st_mode) or st.st_size > MAX_FILE_BYTES:
        return None
    return real


def in_run(run_dir: Path, relative: str) -> Path | None:
    """The run's file `relative` (see regular_file), or None."""
    root = Path(os.path.realpath(run_dir))
    return regular_file(root / relative, (root,))


def is_png(path: Path) -> bool:
    """A PNG: its signature, then an IHDR chunk of 13 bytes with a width and height > 0."""
    try:
        with open(path, "rb") as f:
            head = f.read(24)
    except OSError:
        return False
    if len(head) < 24 or not head.startswith(PNG_SIGNATURE) or head[12:16] != b"IHDR":
        return False
    length, width, height = struct.unpack(">I4xII", head[8:24])
    return length == 13 and width > 0 and height > 0


def map_picture(run_dir: Path, named) -> tuple[Path | None, str | None]:
    """(the map picture to serve, None) or (None, why the map that config.json names is not
    served); (None, None) for a run on the empty terrain. The run's own copy (map.png in
    its directory) first, then what config.json names (a relative name from the run
    directory or the working directory), if inside the run directory or one of the
    packaged maps."""
    root = Path(os.path.realpath(run_dir))
    own = in_run(root, RUN_MAP)
    if own is not None and is_png(own):
        return own, None
    if named is None or named == "":
        return None, None
    if not isinstance(named, str):
        return None, "config.json's map is not a path"
    # A relative name as the run was given it (from its working directory, most often the
    # repository's root for a packaged map), or from the run directory: either way only
    # what lies in the run directory or among the packaged maps is taken.
    found = None
    for base in (root, Path.cwd()):
        found = found or regular_file(base / named, (root, PACKAGED_MAPS))
    if found is None:
        return None, (
            f"the run's map {named[:200]!r} is neither in the run directory nor one of the "
            "packaged maps (or not a regular file): not served"
        )
    if not is_png(found):
        return None, f"the run's map {named[:200]!r} is not a PNG: not served"
    return found, None


def snapshot_steps(run_dir: Path) -> list[int]:
    """The steps at which the display robot saved its merged map (display/step-NNNNN.png)."""
    steps = []
    try:
        entries = list(Path(layout.display_dir(run_dir)).glob("step-*.png"))
    except OSError:
        return []
    for p in entries:
        digits = p.stem.removeprefix("step-")
        if digits.isascii() and digits.isdigit() and len(digits) <= 9:
            steps.append(int(digits))
    return sorted(steps)


def snapshot(run_dir: Path, step: int) -> Path | None:
    """The display's snapshot of `step`, if the run saved one that may be served (looked
    up among the files the run wrote, never built from what a request says)."""
    if step not in snapshot_steps(run_dir):
        return None
    found = in_run(run_dir, f"display/step-{step:05d}.png")
    return found if found is not None and is_png(found) else None
