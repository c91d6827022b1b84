"""Mobility traces: ns-2 movement files (BonnMotion's NSFile, CORE, setdest) and ONE traces,
parsed into per-node motions and sampled at any time.

Theory of operation. A trace is parsed once into a `Trace`: each node's initial position and
its timed way-points. Sampling is a pure function of time (`Trace.positions(t)`), so the
player (topology.player) only has to pick the times: the tick's.

ns-2 (what BonnMotion's NSFile and CORE write, and ns-3's Ns2MobilityHelper reads):

    $node_(0) set X_ 12.5                      initial position (Z_ is read and ignored)
    $ns_ at 3.0 "$node_(0) setdest 40 12.5 2.0"   at t=3 s head for (40, 12.5) at 2 m/s

`$ns` is accepted for `$ns_`. A setdest starts from wherever the node is at that time (the
previous leg may be unfinished: it is abandoned there, as ns-2 does) and moves in a straight
line at constant speed; on arrival the node stops exactly at the destination. Speed 0 means
no motion. Node i (from 0) is robot i+1. Comments (#) and blank lines are skipped.

ONE (the Opportunistic Network Environment's external movement format): an optional first
line of 6 or 8 numbers (the bounds), then `time id x y` lines; the node is at (x, y) at that
time and moves in a straight line to its next sample. Before its first sample a node is at
that sample; after its last, it stays there.

A bad file is a `TraceError` whose message names the line and what is wrong with it.
"""

from __future__ import annotations

import bisect
import math
import re
from dataclasses import dataclass, field

Position = tuple[float, float]

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
    motions: list[Motion]  # motions[i] is node i, robot i + 1

    @property
    def nodes(self) -> int:
        return len(self.motions)

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
        raise _fail(where, n, f"{what} must be finite, not {value}")
    return v


def parse_ns2(text: str, where: str = "trace") -> Trace:
    initial: dict[int, dict[str, float]] = {}
    legs: list[tuple[float, int, int, float, float, float]] = []  # (t, line, node, x, y, v)
    for n, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        if m := _SET.match(line):
            node, axis = int(m[1]), m[2]
            initial.setdefault(node, {})[axis] = _finite(m[3], where, n, f"{axis}_")
        elif m := _AT.match(line):
            t = _finite(m[1], where, n, "time")
            if t < 0:
                raise _fail(where, n, f"time {m[1]} is negative")
            x, y = _finite(m[3], where, n, "x"), _finite(m[4], where, n, "y")
            speed = _finite(m[5], where, n, "speed")
            if speed < 0:
                raise _fail(where, n, f"speed {m[5]} is negative")
            legs.append((t, n, int(m[2]), x, y, speed))
        else:
            shown = line if len(line) <= 60 else line[:57] + "..."
            raise _fail(
                where, n, f"not an ns-2 movement line ('$node_(i) set X_ x' or "
                f"'$ns_ at T \"$node_(i) setdest X Y SPEED\"'): {shown}",
            )  # fmt: skip
    if not initial:
        raise TraceError(f"{where}: no node has an initial position ($node_(i) set X_ ...)")
    for node, axes in sorted(initial.items()):
        if "X" not in axes or "Y" not in axes:
            raise TraceError(
                f"{where}: node {node} has no initial {'X_' if 'X' not in axes else 'Y_'}"
            )
    count = max(initial) + 1
    missing = [i for i in range(count) if i not in initial]
    if missing:
        raise TraceError(
            f"{where}: node {missing[0]} has no initial position (nodes 0..{count - 1})"
        )
    motions = [Motion([0.0], [(initial[i]["X"], initial[i]["Y"])]) for i in range(count)]
    for t, n, node, x, y, speed in sorted(legs, key=lambda leg: (leg[0], leg[1])):
        if node >= count:
            raise _fail(where, n, f"node {node} has no initial position")
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
        mo.times.append(t + d / speed)
        mo.points.append((x, y))
    return Trace(motions)


def parse_one(text: str, where: str = "trace") -> Trace:
    samples: dict[int, list[tuple[float, float, float]]] = {}
    first = True
    for n, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        parts = line.split()
        try:
            values = [float(p) for p in parts]
        except ValueError:
            raise _fail(where, n, f"not a ONE line 'time id x y': {line[:60]}") from None
        if first and len(parts) in (6, 8):
            first = False
            continue  # the bounds header
        first = False
        if len(parts) != 4:
            raise _fail(where, n, f"expected 4 fields 'time id x y', found {len(parts)}")
        t, node, x, y = values
        if not all(math.isfinite(v) for v in values) or t < 0:
            raise _fail(where, n, "time, x and y must be finite and time >= 0")
        if node != int(node) or node < 0:
            raise _fail(where, n, f"node id {parts[1]} is not a whole number >= 0")
        samples.setdefault(int(node), []).append((t, x, y))
    if not samples:
        raise TraceError(f"{where}: no samples")
    count = max(samples) + 1
    missing = [i for i in range(count) if i not in samples]
    if missing:
        raise TraceError(f"{where}: node {missing[0]} has no sample (nodes 0..{count - 1})")
    motions = []
    for i in range(count):
        pts = sorted(samples[i], key=lambda s: s[0])
        motions.append(Motion([p[0] for p in pts], [(p[1], p[2]) for p in pts]))
    return Trace(motions)


def parse(text: str, where: str = "trace") -> Trace:
    """An ns-2 file if any line starts with `$`, else a ONE trace."""
    if any(line.lstrip().startswith("$") for line in text.splitlines()):
        return parse_ns2(text, where)
    return parse_one(text, where)


def load(path: str) -> Trace:
    try:
        with open(path) as f:
            text = f.read()
    except OSError as exc:
        raise TraceError(f"{path}: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise TraceError(f"{path}: not a text file") from None
    return parse(text, path)


def ticks(end: float, tick: float) -> list[float]:
    """The sampling times 0, tick, 2 tick, ... up to the first at or past `end` (and `end`
    itself, so that every node's final position is applied)."""
    n = math.ceil(end / tick - 1e-9) if end > 0 else 0
    out = [round(k * tick, 9) for k in range(n + 1)]
    if out[-1] < end:
        out.append(end)
    return out
