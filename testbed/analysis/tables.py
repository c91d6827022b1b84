"""The numbers behind the figures: pure functions of a sweep's runs (`FinishedRun`s).

Theory of operation. Each figure of the report is drawn from one table (a list of frozen
dataclass rows, declared here; the records they share in testbed.analysis.rows) computed
here and written next to it as CSV and JSON (`write_table`), so a reader or a test can
check a figure against the runs' own result.json; the report's verdicts are decided on the
same tables. Which runs count is the caller's choice of runs plus `FinishedRun.usable` and
`.unimpaired` (testbed.analysis.runs).

- `fig2_rows`: exploration steps per (variant, laser, range, team size) with each point's
  spread and the 95% interval of its mean (testbed.analysis.stats). A point of one run has
  no spread: its std and interval are empty (None), not 0. A team past the paper's ten
  (`Fig2Row.beyond_paper`; testbed/experiments/paper-large-teams.toml) is marked in Fig. 2.
- `fig4_runs` / `fig4_rows`: the plan intervals of one run per team size (teams 1, 2, 5 and
  10 at laser 2 m and range 20 m where they ran).
- `plan_cause_rows`: plan generations by cause, per run.
- `routing_per_run`, `routing_rows`: routing metrics from the captures, per run and per
  (range, team size); `impairment_rows`: steps and PDF against loss and delay.
"""

from __future__ import annotations

import csv
import io
import json
import logging
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, TypeVar

from common.jsonfile import write_atomic
from testbed.analysis.rows import INLINE, MeanRange, Measures, Spread, columns, named
from testbed.analysis.runs import DEFAULT_VARIANT, FinishedRun
from testbed.files.routingfile import DaemonComparison, RoutingMetrics
from topology.spec import VETH

FIG4_TEAMS = (1, 2, 5, 10)
PAPER_MAX_TEAM = 10  # the paper's team sizes are 1-10: larger ones are beyond its range
FIG4_LASER = 2.0
FIG4_RANGE = 20.0
ROUTING_METRICS = (
    ("overhead_packets", "routing overhead (control / all packets)"),
    ("pdf", "packet delivery fraction"),
    ("delay_ms_median", "end-to-end delay, median (ms, wall clock)"),
    ("throughput_bps", "throughput (bit/s, wall clock)"),
)

log = logging.getLogger(__name__)

MetricsOf = Callable[[FinishedRun], "RoutingMetrics | None"]
USUAL_CAUSES = ("start", "timer", "request")


@dataclass(frozen=True)
class PlanInterval:
    """A plan generation after a robot's first: its step, cause and interval since the last."""

    robot: str
    step: int
    interval: int
    cause: str | None


@dataclass(frozen=True)
class Fig2Row:
    """A Fig. 2 point: exploration steps of a (variant, laser, range, team size) over runs."""

    coordination: str
    start_placement: str
    laser_range: float
    comm_range: float
    robots: int
    steps: Spread = field(metadata=INLINE)
    steps_per_run: tuple[float, ...]
    runs: tuple[str, ...]

    @property
    def variant(self) -> tuple[str, str]:
        return self.coordination, self.start_placement

    @property
    def beyond_paper(self) -> bool:
        """A team larger than the paper's (PAPER_MAX_TEAM): Fig. 2 marks it."""
        return self.robots > PAPER_MAX_TEAM


@dataclass(frozen=True)
class Fig4Row:
    """A plan interval of the run Fig. 4 shows for a team size."""

    robots: int
    comm_range: float
    laser_range: float
    run: str
    plan: PlanInterval = field(metadata=INLINE)


@dataclass(frozen=True)
class PlanCauseRow:
    """A usable unimpaired run's plan generations by cause."""

    run: str
    coordination: str
    start_placement: str
    robots: int
    comm_range: float
    laser_range: float
    start: int
    timer: int
    request: int
    other_causes: Mapping[str, int] = field(default_factory=dict, metadata=INLINE)

    @property
    def variant(self) -> tuple[str, str]:
        return self.coordination, self.start_placement


@dataclass(frozen=True)
class RoutingRun:
    """A usable run's routing metrics from its captures."""

    run: str
    robots: int
    comm_range: float
    laser_range: float
    loss_pct: float
    delay_ms: float
    time_scale: float | None
    tcp_emulated: bool  # may PDF and delay meet other scales'
    overhead_packets: float | None
    pdf: float | None
    delay_ms_median: float | None
    throughput_bps: float | None
    delay_ms_median_emulated: float | None
    control_tx_packets: float | None  # a count (routingfile: a number, not negative)
    tx_packets: float | None
    daemon_tx_packets: float | None
    daemon_relative_difference: float | None
    capture_dropped_packets: float | None


@dataclass(frozen=True)
class RoutingMeans(Measures):
    """Each routing metric's mean and range over a point's runs (ROUTING_METRICS, then the
    emulated delay)."""

    overhead_packets: MeanRange
    pdf: MeanRange
    delay_ms_median: MeanRange
    throughput_bps: MeanRange
    delay_ms_median_emulated: MeanRange


@dataclass(frozen=True)
class RoutingRow:
    """Routing metrics per (range, team size) over the unimpaired runs, lasers pooled."""

    comm_range: float
    robots: int
    n: int
    means: RoutingMeans = field(metadata=INLINE)
    time_scales: tuple[float, ...]
    tcp_emulated: bool


@dataclass(frozen=True)
class ImpairmentRun:
    """A usable run's exploration steps and PDF at its loss and delay."""

    robots: int
    comm_range: float
    delay_ms: float
    loss_pct: float
    steps: float | None
    pdf: float | None


@dataclass(frozen=True)
class ImpairmentRow:
    """Exploration steps and PDF per (team, range, delay, loss)."""

    robots: int
    comm_range: float
    delay_ms: float
    loss_pct: float
    n: int
    steps: MeanRange
    pdf: MeanRange

    def of(self, metric: str) -> MeanRange:
        """`steps` or `pdf`."""
        return named(self, metric, IMPAIRMENT_METRICS)


ROUTING_FIELDS = tuple(f.name for f in fields(RoutingMeans))
IMPAIRMENT_METRICS = ("steps", "pdf")


def plan_intervals(run: FinishedRun) -> list[PlanInterval]:
    """Each plan generation after a robot's first: its step, cause and interval."""
    rows = []
    for robot in run.robots_by_number():
        plans = sorted(robot.plans, key=lambda p: p.step)
        for prev, cur in zip(plans, plans[1:], strict=False):
            rows.append(PlanInterval(robot.name, cur.step, cur.step - prev.step, cur.cause))
    return rows


MAIN_NETWORK = ("aodv", "empty", VETH)


def main_network(runs: list[FinishedRun]) -> tuple[str, str, str]:
    """(routing, map, medium) the paper's figures are drawn for when a sweep varied them (a
    protocols or media sweep): AODV on the empty terrain over veth where it ran."""
    present = {r.network for r in runs if r.usable}
    return MAIN_NETWORK if MAIN_NETWORK in present or not present else min(present)


def main_variant(runs: list[FinishedRun]) -> tuple[str, str]:
    """The variant the paper's figures are drawn for: the default where it ran."""
    present = {r.variant for r in runs if r.usable}
    return DEFAULT_VARIANT if DEFAULT_VARIANT in present or not present else min(present)


def fig2_rows(runs: list[FinishedRun]) -> list[Fig2Row]:
    """Exploration steps per (variant, laser, range, team size) over the usable unimpaired
    runs, with the 95% confidence interval of each point's mean."""
    groups: dict[tuple, list[tuple[str, float]]] = {}
    for run in runs:
        if not (run.usable and run.unimpaired):
            continue
        steps = run.exploration_steps
        if steps is None:
            continue
        c = run.config
        key = (*run.variant, c.laser_range, c.comm_range, c.robots)
        groups.setdefault(key, []).append((run.run_id, steps))
    rows = []
    for (coord, start, laser, comm, robots), items in sorted(
        groups.items(), key=lambda kv: (kv[0][:2], -kv[0][2], *kv[0][3:])
    ):
        per_run = [s for _, s in items]
        rows.append(Fig2Row(coord, start, laser, comm, robots, Spread.of(per_run),
                            tuple(per_run), tuple(rid for rid, _ in items)))  # fmt: skip
    return rows


def fig4_runs(runs: list[FinishedRun]) -> list[FinishedRun]:
    """The runs Fig. 4 shows: one per team size (first run of the point), laser 2 m and range
    20 m where present (else the largest laser and range), teams 1, 2, 5, 10 where present
    (else up to four team sizes that ran)."""
    main = main_variant(runs)
    cands = [r for r in runs if r.usable and r.unimpaired and r.variant == main]
    if not cands:
        return []
    lasers = {r.config.laser_range for r in cands}
    laser = FIG4_LASER if FIG4_LASER in lasers else max(lasers)
    cands = [r for r in cands if r.config.laser_range == laser]
    ranges = {r.config.comm_range for r in cands}
    comm = FIG4_RANGE if FIG4_RANGE in ranges else max(ranges)
    cands = [r for r in cands if r.config.comm_range == comm]
    by_team: dict[int, FinishedRun] = {}
    for r in sorted(cands, key=lambda r: r.run_id):
        by_team.setdefault(r.config.robots, r)
    teams = [n for n in FIG4_TEAMS if n in by_team]
    teams += [n for n in sorted(by_team) if n not in teams][: 4 - len(teams)]
    return [by_team[n] for n in sorted(teams)]


def fig4_rows(runs: list[FinishedRun]) -> list[Fig4Row]:
    rows = []
    for run in fig4_runs(runs):
        c = run.config
        for plan in plan_intervals(run):
            rows.append(Fig4Row(c.robots, c.comm_range, c.laser_range, run.run_id, plan))
    return rows


def plan_cause_rows(runs: list[FinishedRun]) -> list[PlanCauseRow]:
    """Per usable unimpaired run: how many plan generations each cause produced."""
    rows = []
    for run in runs:
        if not (run.usable and run.unimpaired):
            continue
        counts = dict.fromkeys(USUAL_CAUSES, 0)
        for robot in run.robots:
            for p in robot.plans:
                cause = p.cause if p.cause is not None else "other"
                counts[cause] = counts.get(cause, 0) + 1
        c = run.config
        start, timer, request = (counts.pop(k) for k in USUAL_CAUSES)
        rows.append(PlanCauseRow(run.run_id, *run.variant, c.robots, c.comm_range,
                                 c.laser_range, start, timer, request, counts))  # fmt: skip
    return rows


def routing_per_run(runs: list[FinishedRun], metrics_of: MetricsOf) -> list[RoutingRun]:
    """One row per usable run that has captures: its routing metrics (metrics_of(run): its
    routing.json, testbed.analysis.pcapmetrics)."""
    rows = []
    for run in runs:
        if not run.usable:
            continue
        m = metrics_of(run)
        if not m:
            continue
        c = run.config
        cmp = m.daemon_comparison or DaemonComparison()
        rows.append(RoutingRun(
            run=run.run_id, robots=c.robots, comm_range=c.comm_range,
            laser_range=c.laser_range, loss_pct=c.loss_pct, delay_ms=c.delay_ms,
            time_scale=run.time_scale_requested or c.time_scale,
            tcp_emulated=run.tcp_in_emulated_time,
            overhead_packets=m.overhead_packets, pdf=m.pdf,
            delay_ms_median=m.delay_ms_median, throughput_bps=m.throughput_bps,
            delay_ms_median_emulated=m.emulated.delay_ms_median if m.emulated else None,
            control_tx_packets=m.control_tx_packets, tx_packets=m.tx_packets,
            daemon_tx_packets=cmp.daemon_tx_packets,
            daemon_relative_difference=cmp.relative_difference,
            capture_dropped_packets=m.capture_dropped_packets,
        ))  # fmt: skip
    return rows


Row = TypeVar("Row")
Key = TypeVar("Key", bound=tuple)


def aggregate(
    rows: Sequence[Row], key: Callable[[Row], Key], metrics: tuple[str, ...]
) -> list[tuple[Key, list[Row], dict[str, MeanRange]]]:
    """Per value of key(row), in its order: the rows, and each metric's (a field of the rows,
    by name) mean, min and max over them (None when no row has it)."""
    groups: dict[Key, list[Row]] = {}
    for r in rows:
        groups.setdefault(key(r), []).append(r)
    out = []
    for k, items in sorted(groups.items(), key=lambda kv: kv[0]):
        means = {}
        for m in metrics:
            means[m] = MeanRange.of([v for i in items if (v := getattr(i, m)) is not None])
        out.append((k, items, means))
    return out


def routing_rows(per_run: list[RoutingRun]) -> list[RoutingRow]:
    """Routing metrics per (range, team size) over the unimpaired runs, lasers pooled; with
    the time scales they ran at and whether TCP kept emulated time in every one of them."""
    base = [r for r in per_run if not r.loss_pct and not r.delay_ms]
    rows = []
    for (comm, robots), runs, means in aggregate(
        base, lambda r: (r.comm_range, r.robots), ROUTING_FIELDS
    ):
        rows.append(RoutingRow(
            comm_range=comm, robots=robots, n=len(runs), means=RoutingMeans(**means),
            time_scales=tuple(sorted({r.time_scale for r in runs if r.time_scale})),
            tcp_emulated=all(r.tcp_emulated for r in runs),
        ))  # fmt: skip
    return rows


def impairment_rows(runs: list[FinishedRun], per_run: list[RoutingRun]) -> list[ImpairmentRow]:
    """Exploration steps and PDF per (team, range, delay, loss) when the sweep varied loss or
    delay; empty otherwise."""
    usable = [r for r in runs if r.usable]
    if len({(r.config.loss_pct, r.config.delay_ms) for r in usable}) < 2:
        return []
    pdf = {r.run: r.pdf for r in per_run}
    each = [ImpairmentRun(r.config.robots, r.config.comm_range, r.config.delay_ms,
                          r.config.loss_pct, r.exploration_steps, pdf.get(r.run_id))
            for r in usable]  # fmt: skip
    return [
        ImpairmentRow(robots, comm, delay, loss, len(items), **means)
        for (robots, comm, delay, loss), items, means in aggregate(
            each, lambda r: (r.robots, r.comm_range, r.delay_ms, r.loss_pct), IMPAIRMENT_METRICS
        )
    ]


def _finite_rows(rows: Sequence[Any], stem: Path) -> list[dict[str, Any]]:
    """Each row's columns (testbed.analysis.rows.columns) with every number that is not
    finite (a NaN mean) as None, each said in the log: a table never holds NaN silently, and
    its JSON stays strict."""
    out = []
    for row in rows:
        r = columns(row)
        bad = [k for k, v in r.items() if isinstance(v, float) and not math.isfinite(v)]
        for k in bad:
            point = {k2: v for k2, v in r.items() if k2 in ("robots", "comm_range")}
            log.warning("%s: %s of %s is %s, not a number: left empty", stem.name, k, point, r[k])
        out.append({k: None if k in bad else v for k, v in r.items()})
    return out


def write_table(rows: Sequence[Any], stem: Path) -> None:
    """rows (frozen dataclass rows, in their columns) as stem.csv (sequences joined by ';')
    and stem.json; a number that is not finite is written empty, and said (_finite_rows)."""
    cells = _finite_rows(rows, stem)
    write_atomic(stem.with_suffix(".json"), json.dumps(cells, indent=1) + "\n")
    names: list[str] = []
    for r in cells:
        names += [k for k in r if k not in names]
    f = io.StringIO(newline="")
    w = csv.DictWriter(f, fieldnames=names)
    w.writeheader()
    for r in cells:
        w.writerow({k: ";".join(map(str, v)) if isinstance(v, list | tuple) else v
                    for k, v in r.items()})  # fmt: skip
    write_atomic(stem.with_suffix(".csv"), f.getvalue())
