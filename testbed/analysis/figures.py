"""Figures of a sweep: the paper's Figs. 2 to 5, routing metrics and impairments.

Theory of operation. `make_all` reads a sweep directory's finished runs once
(testbed.analysis.runs), computes the table behind each figure (testbed.analysis.tables),
writes each table as CSV and JSON into `DIR/figures/` and draws it as PNG and PDF
(testbed.analysis.plots), so a test (or a reader) can check a figure against the runs' own
results. It returns the runs and the tables, which the report decides its verdicts on.
The comparisons a sweep makes when it varies one choice (routing protocols, media,
middlewares) are `STUDIES`, one entry each: its sweep file, what it compares, its tables and
its report section; a new one is an entry there and its two fields in `Tables`.

Which runs count: runs whose status is `complete` or `step_cap` (a run that hit the step cap
counts its unfinished robots at the final step, as the contract says). Runs that crashed or
failed are left out and counted by the report, and so are runs not faithful to their time
scale (testbed.run.fidelity) unless `testbed report --include-unfaithful`. The paper's
figures use the unimpaired runs (loss 0, delay 0) of one routing on one map (AODV on the
empty terrain where it ran; a protocols sweep compares the others in its own section); the
impairment figures exist when a sweep varies loss or delay. A sweep that varies the middleware
or a battery failure has them drawn for the default middleware without a failure
(testbed.analysis.middlewares compares them all).

- Fig. 2(a)/(b): exploration steps of a run (mean over robots of finish_step) against team
  size, one line per communication range; the point is the mean over runs, the error bar its
  95% confidence interval (testbed.analysis.stats: Student's t over the point's runs). (a)
  laser 2 m, (b) laser 1.5 m (or whatever lasers ran). A sweep that varies coordination or
  start placement (an ablation) has its Figs. 2 and 4 drawn for its main variant (`ours` and
  `corner` where it ran, else the first that did); testbed.analysis.ablation shows them all.
- Fig. 4(a)-(d): for teams of 1, 2, 5 and 10 (laser 2 m, range 20 m, first run of the point),
  each plan generation's interval since the same robot's previous one, against the step it
  happened at, by cause, with the 20-step timer as a reference line.
- Figs. 3 and 5: each point's first run's paths over the display's map (testbed.analysis.
  pathsfig), under figures/paths/.
- Routing: overhead, packet delivery fraction, end-to-end delay and throughput from the pcaps
  (testbed.analysis.pcapmetrics) against team size, one line per range (all laser ranges pooled).
- Impairments: exploration steps and packet delivery fraction against link loss.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

from common import boundedfile
from common.jsonfile import make_dirs, write_atomic
from testbed.analysis import (
    ablation,
    media,
    middlewares,
    pathsfig,
    pcapmetrics,
    plots,
    protocols,
    tables,
)
from testbed.analysis.ablation import ThirdsRow
from testbed.analysis.media import MediaPoint, MediaRun
from testbed.analysis.middlewares import MiddlewarePoint, MiddlewareRun
from testbed.analysis.protocols import ProtocolPoint, ProtocolRun
from testbed.analysis.runs import FinishedRun, load_runs
from testbed.analysis.tables import (
    Fig2Row,
    Fig4Row,
    ImpairmentRow,
    MetricsOf,
    PlanCauseRow,
    RoutingRow,
    RoutingRun,
    write_table,
)
from testbed.files.routingfile import RoutingMetrics
from testbed.view import served

log = logging.getLogger(__name__)


@dataclass
class Tables:
    """The tables behind a sweep's figures and sections (each empty when the sweep has no
    data for it): what the report renders and decides its verdicts on."""

    fig2: list[Fig2Row] = field(default_factory=list)  # the main variant's points
    fig2_all: list[Fig2Row] = field(default_factory=list)  # every variant's
    fig4: list[Fig4Row] = field(default_factory=list)
    plans: list[PlanCauseRow] = field(default_factory=list)  # the main variant's runs
    ablation_thirds: list[ThirdsRow] = field(default_factory=list)
    protocols_runs: list[ProtocolRun] = field(default_factory=list)
    protocols: list[ProtocolPoint] = field(default_factory=list)
    media_runs: list[MediaRun] = field(default_factory=list)
    media: list[MediaPoint] = field(default_factory=list)
    middlewares_runs: list[MiddlewareRun] = field(default_factory=list)
    middlewares: list[MiddlewarePoint] = field(default_factory=list)
    routing_runs: list[RoutingRun] = field(default_factory=list)
    routing: list[RoutingRow] = field(default_factory=list)
    impairments: list[ImpairmentRow] = field(default_factory=list)


@dataclass(frozen=True)
class Study:
    """A comparison a sweep makes when it varies one choice (its sweep file in
    testbed/experiments/): its tables, written as figures/NAME_runs and figures/NAME and kept
    in Tables' fields of the same names, and its section of the report."""

    name: str
    sweep: str  # the sweep file that runs it (testbed/experiments/)
    varies: Callable[[FinishedRun], object]  # what it compares (the study is made for 2 or more)
    # (the sweep's runs, each run id's capture metrics) -> (per-run rows, point rows)
    tables: Callable[[list[FinishedRun], dict], tuple[list, list]]
    section: Callable[[list], list[str]]  # the report's section, from the point rows


STUDIES = (
    Study("protocols", "protocols.toml", lambda r: r.config.routing, protocols.tables,
          protocols.section),
    Study("media", "media.toml", lambda r: r.config.medium, media.tables, media.section),
    Study("middlewares", "middleware.toml", middlewares.middleware_of, middlewares.tables,
          middlewares.section),
)  # fmt: skip


@dataclass
class Made:
    """What `make_all` made: the files written, the sweep's runs, the tables, and why the
    runs left out were (one line each)."""

    runs: list[FinishedRun]
    files: list[Path] = field(default_factory=list)
    tables: Tables = field(default_factory=Tables)
    left_out: list[str] = field(default_factory=list)


def capture_metrics(run: FinishedRun) -> RoutingMetrics | None:
    """The run's routing metrics from its captures (None without captures or tshark)."""
    try:
        return pcapmetrics.run_metrics(run.path, run=run)
    except OSError as e:  # tshark missing or a capture unreadable
        log.warning("%s: no routing metrics: %s", run.run_id, e)
        return None


def collect_paths(runs: list[FinishedRun], dest: Path) -> list[Path]:
    """The path pictures (Figs. 3 and 5) of each point's first usable run: drawn from its
    positions (testbed.analysis.pathsfig: start markers, a scale bar, names inside the
    frame), or its own paths.png copied where it recorded no positions."""
    make_dirs(dest, root=dest.parent)  # figures/paths: a directory of its own, not a link
    seen, out = set(), []
    for run in sorted(runs, key=lambda r: r.run_id):
        c = run.config
        point = (c.robots, c.comm_range, c.laser_range, c.loss_pct, c.delay_ms)
        src = run.path / "paths.png"
        if not run.usable or point in seen:
            continue
        try:
            png = pathsfig.write_paths(run, dest / run.run_id)
        except pathsfig.PathsError as e:
            log.warning("no paths picture: %s", e)
            continue
        if png is None:
            png = _copy_paths_png(src, dest / f"{run.run_id}.png")
        if png is not None:
            seen.add(point)
            out.append(png)
    return out


def _copy_paths_png(src: Path, dest: Path) -> Path | None:
    """A run's own paths.png copied to `dest` when it is a regular PNG file inside its
    run directory (a link out of it, a FIFO or a non-PNG is left out), else None."""
    found = served.in_run(src.parent, src.name)
    if found is None or not served.is_png(found):
        return None
    try:
        data = boundedfile.read(found, served.MAX_FILE_BYTES)
    except boundedfile.Refused:
        return None
    write_atomic(dest, data)
    return dest


def _paper_figures(runs: list[FinishedRun], figdir: Path, made: Made) -> None:
    """Figs. 2 and 4, the plan causes, and the ablation's tables when variants ran."""
    t = made.tables
    t.fig2_all = tables.fig2_rows(runs)
    write_table(t.fig2_all, figdir / "fig2")
    main = tables.main_variant(runs)
    t.fig2 = [r for r in t.fig2_all if r.variant == main]
    lasers = sorted({r.laser_range for r in t.fig2}, reverse=True)
    for laser, letter in zip(lasers, "abcdefgh", strict=False):
        made.files += plots.plot_fig2(t.fig2, laser, figdir / f"fig2{letter}", letter)

    t.fig4 = tables.fig4_rows(runs)
    write_table(t.fig4, figdir / "fig4")
    if t.fig4:
        made.files += plots.plot_fig4(t.fig4, figdir / "fig4")
    plans = tables.plan_cause_rows(runs)
    write_table(plans, figdir / "plans")
    t.plans = [r for r in plans if r.variant == main]
    if len({r.variant for r in runs if r.usable}) > 1:
        t.ablation_thirds = ablation.request_thirds_rows(runs)
        write_table(t.ablation_thirds, figdir / "ablation_thirds")
        made.files += ablation.plot_fig4_variants(runs, figdir / "ablation_fig4")


def _all_metrics(
    runs: list[FinishedRun], metrics_of: MetricsOf
) -> dict[str, RoutingMetrics | None]:
    """Each run's routing metrics. tshark is the slow part: keep the cores busy with one
    run's captures each."""
    with ThreadPoolExecutor(max_workers=os.cpu_count() or 1) as pool:
        return dict(zip((r.run_id for r in runs), pool.map(metrics_of, runs), strict=True))


def _study_tables(all_runs: list[FinishedRun], metrics: dict, figdir: Path, made: Made) -> None:
    """Each study's tables (STUDIES), when the sweep ran more than one of what it compares."""
    usable = [r for r in all_runs if r.usable]
    for s in STUDIES:
        if len({s.varies(r) for r in usable}) < 2:
            continue
        per_run, points = s.tables(all_runs, metrics)
        setattr(made.tables, f"{s.name}_runs", per_run)
        setattr(made.tables, s.name, points)
        write_table(per_run, figdir / f"{s.name}_runs")
        write_table(points, figdir / s.name)


def _routing_figures(runs: list[FinishedRun], metrics: dict, figdir: Path, made: Made) -> None:
    """Section 2.4's routing metrics, and the impairments when loss or delay varied."""
    t = made.tables
    t.routing_runs = tables.routing_per_run(runs, lambda run: metrics[run.run_id])
    write_table(t.routing_runs, figdir / "routing_runs")
    t.routing = tables.routing_rows(t.routing_runs)
    write_table(t.routing, figdir / "routing")
    if t.routing:
        made.files += plots.plot_routing(t.routing, figdir / "routing")
    t.impairments = tables.impairment_rows(runs, t.routing_runs)
    if t.impairments:
        write_table(t.impairments, figdir / "impairments")
        made.files += plots.plot_impairments(t.impairments, figdir / "impairments")


def make_all(
    sweep_dir: str | Path, metrics_of: MetricsOf | None = None, unfaithful: bool = False
) -> Made:
    """Write every figure the sweep has data for into DIR/figures/; returns what was made
    (`Made`: the files, the runs, the tables). Runs not faithful to their time scale are
    left out unless `unfaithful`."""
    sweep_dir = Path(sweep_dir)
    figdir = make_dirs(sweep_dir / "figures", root=sweep_dir)  # refused if it is a link
    left_out: list[str] = []
    all_runs = load_runs(sweep_dir, unfaithful=unfaithful, left_out=left_out)
    network = tables.main_network(all_runs)
    messaging = middlewares.main_messaging(all_runs)
    runs = [r for r in all_runs if r.network == network
            and (middlewares.middleware_of(r), middlewares.failure_of(r)) == messaging]  # fmt: skip
    made = Made(runs=all_runs, left_out=left_out)
    _paper_figures(runs, figdir, made)
    metrics = _all_metrics(all_runs, metrics_of or capture_metrics)
    _study_tables(all_runs, metrics, figdir, made)
    _routing_figures(runs, metrics, figdir, made)
    made.files += collect_paths(runs, figdir / "paths")
    return made
