"""A run's CSV files as the readers take them: positions.csv (every robot at every step),
links.csv (every link change) and coverage.csv, which testbed.run.files writes.

positions.csv is `step,x1,y1,...,xN,yN`, one row a step from 0, in order; links.csv is
`step,event,i,j`, `event` add or remove, i and j robots 1..N+1 (N+1: the display robot),
never a robot to itself; coverage.csv is `step,coverage`, the share 0..1. Each file starts
with its header.

The files may come from anyone (docs/security.md): `rows(path, parse)` opens one through
common.boundedfile (a regular file, checked on the descriptor it opened), checks the header
where asked (positions.csv's must name each robot of the team once, in order: a header
x1,y1,x1,y1 is not read as robots 1 and 2) and gives each row after it to a row parser of
this module, which checks every value (numbers finite
and within bounds, counts that agree) and raises ValueError saying why; a bad row is a
CsvError naming its line. `read_links` is the link timeline whole.
"""

from __future__ import annotations

import csv
import math
import os
import re
from collections.abc import Callable
from typing import NamedTuple, TypeVar

from common import boundedfile
from topology.names import MAX_ROBOTS
from topology.spec import MAX_COORD_M

POSITIONS_NAME, LINKS_NAME, COVERAGE_NAME = "positions.csv", "links.csv", "coverage.csv"
LINKS_HEADER = ("step", "event", "i", "j")
COVERAGE_HEADER = ("step", "coverage")
MAX_STEP = 10**9
T = TypeVar("T")


_COLUMN = re.compile(r"([xy])([1-9][0-9]{0,3})")


def positions_header(robots: int) -> list[str]:
    return ["step"] + [f"{a}{k}" for k in range(1, robots + 1) for a in "xy"]


def position_columns(header: list[str]) -> list[int]:
    """The robot of each x,y pair of columns of positions.csv's header step,x1,y1,...
    (the display robot, MAX_ROBOTS + 1, may have its own); ValueError when it is not one."""
    if not header or header[0] != "step" or len(header) % 2 != 1:
        raise ValueError("the header is not step,x1,y1,...")
    robots = []
    for x, y in zip(header[1::2], header[2::2], strict=True):
        mx, my = _COLUMN.fullmatch(x), _COLUMN.fullmatch(y)
        if not (mx and my and mx[1] == "x" and my[1] == "y" and mx[2] == my[2]):
            raise ValueError(f"columns {x[:20]!r}, {y[:20]!r} are not xK, yK")
        if int(mx[2]) > MAX_ROBOTS + 1:
            raise ValueError(f"robot {mx[2]} is more than {MAX_ROBOTS + 1}")
        if int(mx[2]) in robots:  # two columns of one robot: whose is the second?
            raise ValueError(f"columns x{mx[2]}, y{mx[2]} name robot {mx[2]} twice")
        robots.append(int(mx[2]))
    return robots


def position_header(robots: int) -> Callable[[list[str]], None]:
    """A check of positions.csv's header for a team of `robots`: step,x1,y1,...,xN,yN, each
    robot once and in order (a reader that takes the columns by place must know whose they
    are); ValueError saying what is wrong."""

    def check(header: list[str]) -> None:
        if len(header) != 1 + 2 * robots:  # as position_rows says it of a row
            raise ValueError(
                f"{len(header)} columns, not {1 + 2 * robots} (step, x and y of {robots})"
            )
        if header != positions_header(robots):
            position_columns(header)  # the reason, where it is one of these
            raise ValueError(f"the header is not step,x1,y1,...,x{robots},y{robots}")

    return check


def coordinate(text: str) -> float:
    """A coordinate of positions.csv (metres, finite, within MAX_COORD_M)."""
    value = float(text)
    if not (math.isfinite(value) and abs(value) <= MAX_COORD_M):
        raise ValueError(f"{text[:40]!r} is not a coordinate")
    return value


class CsvError(ValueError):
    """A row that is not what runs write: `line` (1 the header) and `why`, one line."""

    def __init__(self, line: int, why: str):
        super().__init__(f"line {line}: {why}")
        self.line, self.why = line, why


class LinkChange(NamedTuple):
    step: int
    added: bool  # add (True) or remove
    i: int
    j: int


def finite(text: str, lo: float, hi: float) -> float:
    value = float(text)
    if not (math.isfinite(value) and lo <= value <= hi):
        raise ValueError(f"{text[:40]!r} is not a number in {lo:g}..{hi:g}")
    return value


def whole(text: str, lo: int, hi: int) -> int:
    if not (text.isascii() and text.isdigit() and len(text) <= 10 and lo <= int(text) <= hi):
        raise ValueError(f"{text[:40]!r} is not a whole number in {lo}..{hi}")
    return int(text)


def position_rows(robots: int) -> Callable[[list[str]], list[float]]:
    """A parser of positions.csv's rows for a team of `robots`: each row's coordinates
    (rounded to the millimetre); the rows must come in order, one a step from 0."""
    seen = [0]  # rows read: the step column counts them

    def parse(row: list[str]) -> list[float]:
        if len(row) != 1 + 2 * robots:
            raise ValueError(
                f"{len(row)} columns, not {1 + 2 * robots} (step, x and y of {robots})"
            )
        if whole(row[0], 0, MAX_STEP) != seen[0]:
            raise ValueError(f"step {row[0][:20]!r}, not {seen[0]} (one row a step, in order)")
        seen[0] += 1
        return [round(finite(v, -MAX_COORD_M, MAX_COORD_M), 3) for v in row[1:]]

    return parse


def link_rows(robots: int, last_step: int = MAX_STEP) -> Callable[[list[str]], LinkChange]:
    """A parser of links.csv's rows for a team of `robots` (and its display robot) over
    steps 0..last_step."""

    def parse(row: list[str]) -> LinkChange:
        if len(row) != 4 or row[1] not in ("add", "remove"):
            raise ValueError("not step,add|remove,i,j")
        i, j = (whole(v, 1, robots + 1) for v in row[2:])
        if i == j:
            raise ValueError(f"a link of robot {i} to itself")
        return LinkChange(whole(row[0], 0, max(last_step, 0)), row[1] == "add", i, j)

    return parse


def coverage_row(row: list[str]) -> float:
    """A row of coverage.csv: the share of the free space known."""
    if len(row) != 2:
        raise ValueError("not step,coverage")
    return finite(row[1], 0.0, 1.0)


def rows(
    path: str | os.PathLike[str],
    parse: Callable[[list[str]], T],
    header: Callable[[list[str]], object] | None = None,
) -> list[T]:
    """The rows after the header of the CSV file at `path`, each through `parse` (and the
    header through `header`, when given); boundedfile.Refused when it is not a regular
    file, CsvError for a bad row (line 1: the header)."""
    f = boundedfile.open_text(path)  # checked on the descriptor: no FIFO swapped in
    with f:
        reader = csv.reader(f)
        try:
            first = next(reader, None)
            if header is not None:
                header(first or [])
            return [parse(row) for row in reader]
        except (ValueError, csv.Error) as e:  # UnicodeDecodeError is a ValueError
            why = (str(e).splitlines() or ["unreadable"])[0][:200]
            raise CsvError(reader.line_num, why) from None


def read_links(run_dir: str | os.PathLike[str], robots: int = MAX_ROBOTS) -> list[LinkChange]:
    """A run's link timeline (links.csv), checked (see `rows`)."""
    return rows(os.path.join(run_dir, LINKS_NAME), link_rows(robots))
