"""Does time dilation change the answer? Two sweeps of the same points, side by side.

Theory of operation
-------------------
A lone robot is deterministic, so its invariance across time scales is exact or not at all
(docs/architecture.md, "Time dilation and fidelity"). A team is not: which robot hears what
first is decided by real timing, so the same seed gives different steps from run to run even
at one time scale. Invariance for a team is therefore statistical: the same points run many
times at time scale 1 (emulated time is the wall clock, nothing is late for dilation's sake)
and at a dilated scale, on the same seeds (a run's seed leaves the time scale out), and each
measure's two 95% intervals must overlap (the report's rule for a difference beyond noise,
testbed.analysis.stats).

`compare(dir_a, dir_b)` reads both sweep directories through the typed loader
(testbed.analysis.runs), takes per run the exploration steps (Fig. 2's number), the plans
made on a teammate's request (Fig. 4's), and from the captures (testbed.analysis.pcapmetrics)
the packet delivery fraction, the median and mean delay in emulated ms, TCP's retransmissions
per flow (transmissions of a segment after its first, per direction of a connection that sent
data) and the routing control packets and bytes per robot per second of robot time (the same
per-run numbers as the media section, testbed.analysis.media.run_row). `section` writes the
table and one sentence per measure: at which points the two sweeps agree within the noise, and
at which they do not. Unfaithful runs are left out unless asked for, as in the report.

PDF and delay are the kernel's TCP. Its timers keep emulated time only where the robots'
namespaces had them divided by the time scale (topology.kernel.nettimers; result.json's
`fidelity.network`): at a point whose two sides ran at different scales and where a dilated
run's TCP did not keep emulated time (a kernel before 6.11, a scale past its jiffy, or a run
made before the timers were dilated), TCP's measures (PDF, delays, retransmissions) are not
compared, and the table marks that side's time scale "TCP undilated".

After the measures, the paper's claims as each sweep decides them, and whether the two agree
(testbed.analysis.claimcompare): the report's verdicts, and the deciding design's where both
sweeps have a stage 2 beside them.
"""

from __future__ import annotations

import argparse
import statistics
import sys
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from common.errors import UsageError
from common.jsonfile import write_atomic
from testbed.analysis import claimcompare, media, pcapmetrics, stats
from testbed.analysis.rows import named
from testbed.analysis.runs import FinishedRun, ResultError, load_runs
from testbed.files.routingfile import RoutingMetrics

# (key, name, format)
MEASURES = (
    ("steps", "exploration steps", ".0f"),
    ("requests", "plans on request per robot", ".2f"),
    ("pdf", "packet delivery fraction", ".3f"),
    ("delay_ms", "median delay (emulated ms)", ".2f"),
    ("delay_mean_ms", "mean delay (emulated ms)", ".1f"),
    ("retrans_per_flow", "TCP retransmissions per flow", ".2f"),
    ("control_pkts_per_robot_s", "control packets per robot per second", ".2f"),
    ("control_bytes_per_robot_s", "control bytes per robot per second", ".0f"),
)
# TCP's: compared across time scales only where TCP kept emulated time
NETWORK_MEASURES = ("pdf", "delay_ms", "delay_mean_ms", "retrans_per_flow")
RULE = (
    "the two sweeps agree at a point when the 95% intervals of a measure's means overlap "
    "(Student t; the report's rule for a difference beyond noise)."
)


# A measure's (mean, low, high) over a point's runs, or (mean,) for one run.
Estimate = tuple[float, float, float] | tuple[float]


@dataclass(frozen=True)
class ScaleRun:
    """One run's point and MEASURES, for the comparison of two sweeps."""

    routing: str
    laser_range: float
    comm_range: float
    robots: int
    time_scale: float | None
    tcp_emulated: bool
    steps: float | None
    requests: float | None
    pdf: float | None
    delay_ms: float | None
    delay_mean_ms: float | None
    retrans_per_flow: float | None
    control_pkts_per_robot_s: float | None
    control_bytes_per_robot_s: float | None

    @property
    def point(self) -> tuple[str, float, float, int]:
        return self.routing, self.laser_range, self.comm_range, self.robots

    def measure(self, key: str) -> float | None:
        """One of MEASURES, by name."""
        return named(self, key, MEASURE_KEYS)


@dataclass(frozen=True)
class ScalePoint:
    """A point's runs in one sweep: their number, median time scale, whether TCP kept
    emulated time in all, and each measure's (mean, low, high), or (mean,) for one run."""

    n: int
    time_scale: float | None
    tcp_emulated: bool
    values: Mapping[str, Estimate | None]


MEASURE_KEYS = tuple(k for k, _, _ in MEASURES)


def run_row(run: FinishedRun, metrics: RoutingMetrics | None) -> ScaleRun:
    """One run's measures."""
    row = media.run_row(run, metrics)
    counted = run.counted_robots  # a robot stopped on purpose (--kill) is not averaged
    plans = [p for r in counted for p in r.plans]
    requests = sum(1 for p in plans if p.cause == "request") / len(counted) if counted else None
    scale = run.time_scale_ran
    m = metrics or RoutingMetrics()
    mean = m.delay_ms_mean
    flows, tx, segments = m.tcp_flows, m.tcp_transmissions, m.tcp_segments_sent
    return ScaleRun(
        routing=row.routing, laser_range=run.config.laser_range, comm_range=row.comm_range,
        robots=row.robots, time_scale=scale, tcp_emulated=run.tcp_in_emulated_time,
        steps=row.steps, requests=requests, pdf=row.pdf, delay_ms=row.delay_ms,
        delay_mean_ms=None if mean is None else mean * (scale or 1.0),
        retrans_per_flow=(
            (tx - segments) / flows if flows and tx is not None and segments is not None else None
        ),
        control_pkts_per_robot_s=row.control_pkts_per_robot_s,
        control_bytes_per_robot_s=row.control_bytes_per_robot_s,
    )  # fmt: skip


def rows_of(sweep_dir: str | Path, unfaithful: bool = False) -> tuple[list[ScaleRun], int]:
    """Per-run rows of a sweep directory, and how many finished runs were left out as not
    faithful to their time scale."""
    every = load_runs(sweep_dir, unfaithful=unfaithful)
    kept = [r for r in every if r.usable]
    dropped = sum(1 for r in every if r.faithful is False and not r.usable)
    return [run_row(r, pcapmetrics.run_metrics(r.path, run=r)) for r in kept], dropped


def points(rows: list[ScaleRun]) -> dict[tuple, ScalePoint]:
    """{(routing, laser, range, robots): the point's runs (ScalePoint)}."""
    groups: dict[tuple, list[ScaleRun]] = {}
    for r in rows:
        groups.setdefault(r.point, []).append(r)
    out = {}
    for key, items in sorted(groups.items()):
        scales = [s for i in items if (s := i.time_scale)]
        values: dict[str, Estimate | None] = {}
        for k in MEASURE_KEYS:
            vals = [v for i in items if (v := i.measure(k)) is not None]
            values[k] = stats.mean_ci(vals) or ((statistics.fmean(vals),) if vals else None)
        out[key] = ScalePoint(
            n=len(items),
            time_scale=statistics.median(scales) if scales else None,
            tcp_emulated=all(i.tcp_emulated for i in items),
            values=values,
        )
    return out


def _cell(v, spec: str) -> str:
    if v is None:
        return "–"
    if len(v) == 1:
        return format(v[0], spec)
    return f"{format(v[0], spec)} [{format(v[1], spec)}, {format(v[2], spec)}]"


def _label(point: tuple) -> str:
    routing, laser, comm, robots = point
    return f"{routing}, laser {laser:g} m, range {comm:g} m, {robots} robots"


def comparable(key: str, pa: ScalePoint, pb: ScalePoint) -> bool:
    """Whether a point's measure `key` may be set beside the other sweep's: always, but for
    TCP's measures across time scales where a side's TCP did not keep emulated time."""
    if key not in NETWORK_MEASURES or pa.time_scale == pb.time_scale:
        return True
    return pa.tcp_emulated and pb.tcp_emulated


def sentence(
    key: str,
    name: str,
    spec: str,
    a: dict[tuple, ScalePoint],
    b: dict[tuple, ScalePoint],
    names: tuple[str, str],
) -> str:
    """At which common points `key` agrees within the noise, at which not (and which way)."""
    within, beyond, unknown, undilated = [], [], 0, 0
    for point in sorted(set(a) & set(b)):
        va, vb = a[point].values.get(key), b[point].values.get(key)
        if va is None or vb is None:
            continue
        if not comparable(key, a[point], b[point]):
            undilated += 1
        elif len(va) < 3 or len(vb) < 3:
            unknown += 1
        elif stats.separated(va, vb):
            way = "above" if vb[0] > va[0] else "below"
            beyond.append(
                f"{_label(point)}: {names[1]} {format(vb[0], spec)} {way} "
                f"{names[0]}'s {format(va[0], spec)}"
            )
        else:
            within.append(point)
    judged = len(within) + len(beyond)
    head = f"- {name[0].upper()}{name[1:]}: "
    not_compared = (
        f"not compared at {undilated} point{'s' if undilated != 1 else ''}, where the time "
        "scales differ and TCP's timers were not dilated (result.json's fidelity.network)"
    )
    if not judged:
        if undilated:
            return head + not_compared + "."
        return head + ("not judged: one run on a side." if unknown else "no common point has it.")
    text = head + f"within the noise at {len(within)} of {judged} points"
    text += f"; beyond it at {'; '.join(beyond)}" if beyond else ""
    text += f"; {not_compared}" if undilated else ""
    return text + (f"; {unknown} not judged (one run on a side)." if unknown else ".")


def section(
    a_rows: list[ScaleRun],
    b_rows: list[ScaleRun],
    names: tuple[str, str],
    dropped: tuple[int, int],
) -> list[str]:
    """Markdown: each point's measures in both sweeps, and one sentence per measure."""
    a, b = points(a_rows), points(b_rows)
    out = [
        f"Every cell: the mean over the point's runs with its 95% interval (Student t). "
        f"Runs left out as not faithful to their time scale: {dropped[0]} in {names[0]}, "
        f"{dropped[1]} in {names[1]}.",
        "",
        "| point | sweep | runs | time scale | " + " | ".join(n for _, n, _ in MEASURES) + " |",
        "|---|---|---|---|" + "---|" * len(MEASURES),
    ]
    for point in sorted(set(a) | set(b)):
        for name, side in zip(names, (a, b), strict=True):
            p = side.get(point)
            if p is None:
                continue
            cells = " | ".join(_cell(p.values.get(k), spec) for k, _, spec in MEASURES)
            scale = "–" if p.time_scale is None else f"{p.time_scale:g}"
            if not p.tcp_emulated:
                scale += " (TCP undilated)"
            out.append(f"| {_label(point)} | {name} | {p.n} | {scale} | {cells} |")
    out += ["", f"**Rule.** {RULE}", ""]
    out += [sentence(k, n, spec, a, b, names) for k, n, spec in MEASURES]
    return out + [""]


def compare(dir_a: str | Path, dir_b: str | Path, unfaithful: bool = False) -> list[str]:
    a_rows, a_dropped = rows_of(dir_a, unfaithful)
    b_rows, b_dropped = rows_of(dir_b, unfaithful)
    names = (Path(dir_a).name, Path(dir_b).name)
    return section(a_rows, b_rows, names, (a_dropped, b_dropped))


# ---------------------------------------------------------------- CLI


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("a", metavar="DIR_A", help="a sweep directory (testbed sweep --out)")
    parser.add_argument("b", metavar="DIR_B", help="another, of the same points")
    parser.add_argument("--out", metavar="FILE", help="also write the markdown to FILE")
    parser.add_argument(
        "--include-unfaithful",
        action="store_true",
        help="count runs whose fidelity verdict is false (left out by default)",
    )


def main(args: argparse.Namespace) -> int:
    for d in (args.a, args.b):
        if not (Path(d) / "runs").is_dir():
            raise UsageError(f"{d}: not a sweep directory (no runs/ in it)")
    try:
        lines = compare(args.a, args.b, args.include_unfaithful)
        lines += claimcompare.section(
            claimcompare.claims_of(args.a, args.include_unfaithful),
            claimcompare.claims_of(args.b, args.include_unfaithful),
        )
    except ResultError as e:
        raise UsageError(str(e)) from None
    text = "\n".join(lines)
    sys.stdout.write(text)
    if args.out:
        write_atomic(Path(args.out), text)  # a link named FILE is replaced, not followed
    return 0
