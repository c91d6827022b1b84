"""Mobility traces: ns-2 movement files (BonnMotion's NSFile, CORE, setdest) and ONE traces,
parsed into per-node motions and sampled at any time.

Theory of operation. A trace is parsed once into a `Trace`: each node's initial position and
its timed way-points. Sampling is a pure function of time (`Trace.positions(t)`), so the
player (topology.inputs.player) only has to pick the times: the tick's.

ns-2 (what BonnMotion's NSFile and CORE write, and ns-3's Ns2MobilityHelper reads):

    $node_(0) set X_ 12.5                      initial position (Z_ is read and ignored)
    $ns_ at 3.0 "$node_(0) setdest 40 12.5 2.0"   at t=3 s head for (40, 12.5) at 2 m/s

`$ns` is accepted for `$ns_`. A setdest starts from wherever the node is at that time (the
previous leg may be unfinished: it is abandoned there, as ns-2 does) and moves in a straight
line at constant speed; on arrival the node stops exactly at the destination. Speed 0 means
no motion. Comments (#) and blank lines are skipped.

Nodes and robots (both formats). A file's nodes, in ascending order of id, are robots 1, 2,
...: node i is robot i+1 when the ids are 0..n-1 (BonnMotion, setdest, ONE), and a file whose
ids start elsewhere or have gaps plays as well (CORE numbers its nodes as its canvas does:
6..9 are robots 1..4). `Trace.node_ids` holds the mapping, `mapping_text` says it.

ONE (the Opportunistic Network Environment's external movement format): an optional first
line of 6 or 8 numbers (the bounds), then `time id x y` lines; the node is at (x, y) at that
time and moves in a straight line to its next sample. Before its first sample a node is at
that sample; after its last, it stays there.

ONE (continued): the first line is the header when it has 6 or 8 fields, as the ONE simulator's
ExternalMovementReader requires (`minTime maxTime minX maxX minY maxY [minZ maxZ]`); records
have exactly 4. A header is checked, not skipped: its minimums must not exceed its maximums,
and every record must lie within its time and x, y bounds. A line that is not a header
(a record with two extra fields, say) therefore cannot pass as one and vanish: it is refused
with its line number, or every record after it contradicts it.

Limits (`LIMITS_TEXT`, stated in `net up --help` and docs/guide.md). What a trace may ask for is
bounded by what a testbed and this machine can carry, and checked while parsing, before
anything is allocated for it:

- node ids 0..999: a testbed has at most 1000 robots (topology.names.MAX_ROBOTS), and so a
  file has at most 1000 nodes whatever its ids; a node id of 1e11 is refused, not stored;
- times 0..1e6 s (11.6 days emulated; BonnMotion and ONE scenarios last hours), and a
  node's arrival (start + distance / speed) too, so a speed of 1e-320 is refused rather
  than putting a node's arrival at infinity; coordinates within +-1e6 m, where differences
  and squared distances stay exact to well under a millimetre;
- a regular file of at most 64 MiB (parsing costs about 8 bytes of memory per byte of
  file and 0.07 s per MiB here, and `net up` and the player each parse it: 64 MiB is about
  1 million lines, 0.5 GB and 5 s per process); a FIFO or a device (/dev/zero) is refused
  without reading it;
- lines of at most 1000 characters (a movement line is under 100).

The player's tick (`--tick`) is at least MIN_TICK_S: each tick that moves someone applies
a batch of link changes and saves the state file, which takes a millisecond or more, so a
shorter tick could only ever come late. `ticks()` yields the tick times one at a time.

A bad file is a `TraceError` whose message names the line and what is wrong with it.
"""

from __future__ import annotations

import bisect
import math
import re
from collections.abc import Iterator
from dataclasses import dataclass, field

from common import boundedfile
from topology.names import MAX_ROBOTS

Position = tuple[float, float]

MAX_NODE_ID = MAX_ROBOTS - 1  # ids 0..999: at most MAX_ROBOTS nodes
MAX_TIME_S = 1e6
MAX_COORD_M = 1e6
MAX_FILE_BYTES = 64 * 1024 * 1024
MAX_LINE_CHARS = 1000
MIN_TICK_S = 1e-3
_TIME_TEXT, _COORD_TEXT = "1e6 s", "1e6 m"  # MAX_TIME_S and MAX_COORD_M as the user reads them
LIMITS_TEXT = (
    f"node ids 0..{MAX_NODE_ID}, times (arrivals included) up to {_TIME_TEXT}, "
    f"coordinates within +-{_COORD_TEXT}, a regular file of at most "
    f"{MAX_FILE_BYTES >> 20} MiB with lines of at most {MAX_LINE_CHARS} characters"
)

_NUM = r"([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)"
_SET = re.compile(rf"^\$node_\((\d+)\)\s+set\s+([XYZ])_\s+{_NUM}$")
_AT = re.compile(
    rf"^\$ns_?\s+at\s+{_NUM}\s+\"\$node_\((\d+)\)\s+setdest\s+{_NUM}\s+{_NUM}\s+{_NUM}\s*\"$"
)


class TraceError(ValueError):
    """A trace file that cannot be played: `where: line N: what`."""


@dataclass
class Motion:
    """One node's path: way-points (t, x, y), straight lines between them, still after the
    last. `times` is sorted; the node sits at the first point before it."""

    times: list[float] = field(default_factory=list)
    points: list[Position] = field(default_factory=list)

    def at(self, t: float) -> Position:
        i = bisect.bisect_right(self.times, t)
        if i == 0:
            return self.points[0]
        if i == len(self.times):
            return self.points[-1]
        t0, t1 = self.times[i - 1], self.times[i]
        (x0, y0), (x1, y1) = self.points[i - 1], self.points[i]
        if t1 <= t0:
            return (x1, y1)
        f = (t - t0) / (t1 - t0)
        return (x0 + f * (x1 - x0), y0 + f * (y1 - y0))


@dataclass
class Trace:
    motions: list[Motion]  # motions[k] is robot k + 1
    node_ids: list[int]  # the file's id of motions[k]: its node ids in ascending order

    @property
    def nodes(self) -> int:
        return len(self.motions)

    def robot_of_node(self, robots: int | None = None) -> dict[int, int]:
        """{file node id: robot} of the first `robots` nodes (all by default)."""
        ids = self.node_ids if robots is None else self.node_ids[:robots]
        return {node: k + 1 for k, node in enumerate(ids)}

    def mapping_text(self, robots: int | None = None) -> str:
        """Which file node is which robot, runs of consecutive ids as ranges:
        `nodes 6..9 -> r1..r4`, `nodes 0..3 -> r1..r4, 7 -> r5`."""
        ids = self.node_ids if robots is None else self.node_ids[:robots]
        runs: list[list[int]] = []  # [first id, last id, first robot]
        for k, node in enumerate(ids):
            if runs and node == runs[-1][1] + 1:
                runs[-1][1] = node
            else:
                runs.append([node, node, k + 1])
        parts = [
            f"{a} -> r{r}" if a == b else f"{a}..{b} -> r{r}..r{r + b - a}" for a, b, r in runs
        ]
        return ("nodes " if len(ids) > 1 else "node ") + ", ".join(parts)

    @property
    def end(self) -> float:
        """The time after which nobody moves."""
        return max((m.times[-1] for m in self.motions if m.times), default=0.0)

    def positions(self, t: float, robots: int | None = None) -> list[Position]:
        """Every node's position at emulated time t (the first `robots` nodes)."""
        ms = self.motions if robots is None else self.motions[:robots]
        return [m.at(t) for m in ms]


def _fail(where: str, n: int, what: str) -> TraceError:
    return TraceError(f"{where}: line {n}: {what}")


def _finite(value: str, where: str, n: int, what: str) -> float:
    v = float(value)
    if not math.isfinite(v):
        raise _fail(where, n, f"{what} must be finite, not {_shown(value)}")
    return v


def _shown(text: str, width: int = 40) -> str:
    """A piece of the file as an error message quotes it: at most `width` characters, and
    anything unprintable (a terminal's escape sequences) as a \\x or \\u escape."""
    cut = text if len(text) <= width else text[: width - 3] + "..."
    return "".join(c if c.isprintable() else ascii(c)[1:-1] for c in cut)


def _time(value: str, where: str, n: int, what: str = "time") -> float:
    """A time of the trace: finite, 0..MAX_TIME_S."""
    t = _finite(value, where, n, what)
    if t < 0:
        raise _fail(where, n, f"{what} {_shown(value)} is negative")
    if t > MAX_TIME_S:
        raise _fail(where, n, f"{what} {_shown(value)} is past the limit of {_TIME_TEXT}")
    return t


def _coord(value: str, where: str, n: int, what: str) -> float:
    """A coordinate of the trace: finite, within +-MAX_COORD_M."""
    v = _finite(value, where, n, what)
    if abs(v) > MAX_COORD_M:
        raise _fail(where, n, f"{what} {_shown(value)} is beyond +-{_COORD_TEXT}")
    return v


def _node(text: str, where: str, n: int) -> int:
    """A node id: a whole number 0..MAX_NODE_ID (checked before it is stored)."""
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    whole = math.isfinite(v) and v == int(v)
    if not whole or not 0 <= v <= MAX_NODE_ID:
        raise _fail(
            where, n, f"node id {_shown(text)} is not a whole number 0..{MAX_NODE_ID} "
            f"(a testbed has at most {MAX_ROBOTS} robots)",
        )  # fmt: skip
    return int(v)


def _lines(text: str, where: str) -> Iterator[tuple[int, str]]:
    """(line number, line) of `text`, each at most MAX_LINE_CHARS long."""
    for n, raw in enumerate(text.splitlines(), start=1):
        if len(raw) > MAX_LINE_CHARS:
            raise _fail(where, n, f"{len(raw)} characters long; a trace line has at most "
                        f"{MAX_LINE_CHARS}")  # fmt: skip
        yield n, raw


def parse_ns2(text: str, where: str = "trace") -> Trace:
    initial: dict[int, dict[str, float]] = {}
    legs: list[tuple[float, int, int, float, float, float]] = []  # (t, line, node, x, y, v)
    for n, raw in _lines(text, where):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        if m := _SET.match(line):
            node, axis = _node(m[1], where, n), m[2]
            initial.setdefault(node, {})[axis] = _coord(m[3], where, n, f"{axis}_")
        elif m := _AT.match(line):
            t = _time(m[1], where, n)
            node = _node(m[2], where, n)
            x, y = _coord(m[3], where, n, "x"), _coord(m[4], where, n, "y")
            speed = _finite(m[5], where, n, "speed")
            if speed < 0:
                raise _fail(where, n, f"speed {_shown(m[5])} is negative")
            legs.append((t, n, node, x, y, speed))
        else:
            raise _fail(
                where, n, f"not an ns-2 movement line ('$node_(i) set X_ x' or "
                f"'$ns_ at T \"$node_(i) setdest X Y SPEED\"'): {_shown(line, 60)}",
            )  # fmt: skip
    if not initial:
        raise TraceError(f"{where}: no node has an initial position ($node_(i) set X_ ...)")
    for node, axes in sorted(initial.items()):
        if "X" not in axes or "Y" not in axes:
            raise TraceError(
                f"{where}: node {node} has no initial {'X_' if 'X' not in axes else 'Y_'}"
            )
    ids = sorted(initial)
    motions = {i: Motion([0.0], [(initial[i]["X"], initial[i]["Y"])]) for i in ids}
    for t, n, node, x, y, speed in sorted(legs, key=lambda leg: (leg[0], leg[1])):
        if node not in motions:
            raise _fail(where, n, f"node {node} has no initial position ($node_({node}) set "
                        "X_ ...)")  # fmt: skip
        mo = motions[node]
        here = mo.at(t)
        # A leg in progress is cut at t: drop the way-points after t, end at where we are.
        i = bisect.bisect_right(mo.times, t)
        del mo.times[i:], mo.points[i:]
        if mo.times[-1] < t:
            mo.times.append(t)
            mo.points.append(here)
        d = math.hypot(x - here[0], y - here[1])
        if speed == 0 or d == 0:
            continue
        arrival = t + d / speed
        if not arrival <= MAX_TIME_S:
            raise _fail(
                where, n, f"node {node} would arrive at {arrival:.3g} s ({d:.6g} m at "
                f"{speed:.3g} m/s), past the limit of {_TIME_TEXT}",
            )  # fmt: skip
        mo.times.append(arrival)
        mo.points.append((x, y))
    return Trace([motions[i] for i in ids], ids)


def parse_one(text: str, where: str = "trace") -> Trace:
    samples: dict[int, list[tuple[float, float, float]]] = {}
    header: tuple[int, list[float]] | None = None  # (line, [minT maxT minX maxX minY maxY])
    first = True
    for n, raw in _lines(text, where):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        parts = line.split(None, 8)  # no more than 9 pieces, however long the line
        if first and len(parts) in (6, 8):
            first = False
            header = (n, _one_header(parts, where, n))
            continue
        first = False
        if len(parts) != 4:
            found = f"{len(parts)}" if len(parts) <= 8 else "more than 8"
            raise _fail(where, n, f"expected 4 fields 'time id x y', found {found}")
        for p in parts:
            try:
                float(p)
            except ValueError:
                raise _fail(where, n, f"not a ONE line 'time id x y': {_shown(line, 60)}") from None
        t = _time(parts[0], where, n)
        node = _node(parts[1], where, n)
        x, y = _coord(parts[2], where, n, "x"), _coord(parts[3], where, n, "y")
        if header is not None:
            _within_header(header, (t, x, y), where, n)
        samples.setdefault(node, []).append((t, x, y))
    if not samples:
        raise TraceError(f"{where}: no samples")
    ids = sorted(samples)
    motions = []
    for i in ids:
        pts = sorted(samples[i], key=lambda s: s[0])
        motions.append(Motion([p[0] for p in pts], [(p[1], p[2]) for p in pts]))
    return Trace(motions, ids)


_HEADER = ("minTime", "maxTime", "minX", "maxX", "minY", "maxY", "minZ", "maxZ")


def _one_header(parts: list[str], where: str, n: int) -> list[float]:
    """The ONE header's six (or eight) bounds, checked: numbers, minimum <= maximum."""
    values = []
    for name, p in zip(_HEADER, parts, strict=False):
        try:
            values.append(_finite(p, where, n, f"header {name}"))
        except ValueError:
            raise _fail(
                where, n, "a first line of 6 or 8 fields is the ONE header 'minTime maxTime "
                f"minX maxX minY maxY [minZ maxZ]', and {name} {_shown(p)} is not a number",
            ) from None  # fmt: skip
    for lo in range(0, len(values), 2):
        if values[lo] > values[lo + 1]:
            raise _fail(
                where, n, f"ONE header: {_HEADER[lo]} {values[lo]:g} is above "
                f"{_HEADER[lo + 1]} {values[lo + 1]:g}",
            )  # fmt: skip
    return values[:6]


def _within_header(header: tuple[int, list[float]], sample: tuple[float, float, float],
                   where: str, n: int) -> None:  # fmt: skip
    """A record must lie within the header's bounds (time, x, y)."""
    line, bounds = header
    for k, (name, v) in enumerate(zip(("time", "x", "y"), sample, strict=True)):
        lo, hi = bounds[2 * k], bounds[2 * k + 1]
        if not lo <= v <= hi:
            raise _fail(
                where, n, f"{name} {v:g} is outside the header's {lo:g}..{hi:g} (line "
                f"{line}: the ONE header 'minTime maxTime minX maxX minY maxY')",
            )  # fmt: skip


def parse(text: str, where: str = "trace") -> Trace:
    """An ns-2 file if any line starts with `$`, else a ONE trace."""
    if any(line.lstrip().startswith("$") for line in text.splitlines()):
        return parse_ns2(text, where)
    return parse_one(text, where)


def _refusal(path: str, r: boundedfile.Refused) -> str:
    """The one line that says why trace file `path` was not read."""
    if r.kind == "missing":
        return f"{path}: No such file or directory"
    if r.kind == "directory":
        return f"{path}: is a directory, not a trace file"
    if r.kind == "special":
        return f"{path}: not a regular file (a trace is read from a file, not a pipe or a device)"
    if r.kind == "too_big":
        return (f"{path}: {int(r.detail) >> 20} MiB, over the limit of "
                f"{MAX_FILE_BYTES >> 20} MiB for a trace")  # fmt: skip
    return f"{path}: {r.detail}"


def load(path: str) -> Trace:
    """Parse the trace in file `path`: a regular file of at most MAX_FILE_BYTES, opened
    without blocking (a FIFO is refused, not waited on)."""
    try:
        data = boundedfile.read(path, MAX_FILE_BYTES)
    except boundedfile.Refused as r:
        raise TraceError(_refusal(path, r)) from None
    try:
        text = data.decode()
    except UnicodeDecodeError:
        raise TraceError(f"{path}: not a text file") from None
    return parse(text, path)


def check_tick(tick: float) -> None:
    """ValueError unless `tick` is a usable player tick: finite and at least MIN_TICK_S."""
    if not (math.isfinite(tick) and tick >= MIN_TICK_S):
        raise ValueError(f"tick must be at least {MIN_TICK_S:g} s, not {tick:g}")


def ticks(end: float, tick: float) -> Iterator[float]:
    """The sampling times 0, tick, 2 tick, ... up to the first at or past `end` (and `end`
    itself, so that every node's final position is applied), one at a time."""
    check_tick(tick)
    n = math.ceil(end / tick - 1e-9) if end > 0 else 0
    last = 0.0
    for k in range(n + 1):
        last = round(k * tick, 9)
        yield last
    if last < end:
        yield end
