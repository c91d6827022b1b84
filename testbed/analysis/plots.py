"""Drawing the figures (matplotlib, Agg backend): each plot takes a table of
testbed.analysis.tables and writes PNG and PDF files; nothing here reads a run.

Fig. 2 draws each point's mean with its 95% interval as an error bar; teams past the
paper's ten (tables.PAPER_MAX_TEAM) are drawn hollow on a shaded band labelled as beyond the
paper's range (`fig2_lines` is the data drawn, marks included). The routing and
impairment figures draw min-to-max bars over the point's runs. Fig. 4 scatters each plan
generation's interval against its step, by cause, with the 20-step timer dashed.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import matplotlib
from matplotlib.ticker import MaxNLocator

from common.jsonfile import write_atomic
from testbed.analysis.rows import MeanRange
from testbed.analysis.tables import (
    PAPER_MAX_TEAM,
    ROUTING_METRICS,
    Fig2Row,
    Fig4Row,
    ImpairmentRow,
    RoutingRow,
)

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

PLAN_TIMER_STEPS = 20


def save_figure(fig, path: Path, **kw) -> Path:
    """The figure drawn to memory, then written atomically (common.jsonfile.write_atomic:
    never through a link); the format from the suffix."""
    buf = io.BytesIO()
    fig.savefig(buf, format=path.suffix.lstrip("."), **kw)
    write_atomic(path, buf.getvalue())
    return path


def save(fig, stem: Path) -> list[Path]:
    try:
        out = [save_figure(fig, stem.with_suffix(".png"), dpi=120)]
        out.append(save_figure(fig, stem.with_suffix(".pdf")))
    finally:
        plt.close(fig)
    return out


def _fmt(x: float) -> str:
    return f"{x:g}"


BEYOND_PAPER = f"beyond the paper's range (teams of 1-{PAPER_MAX_TEAM})"


def fig2_lines(rows: list[Fig2Row], laser: float) -> list[tuple[str, list[Point]]]:
    """What Fig. 2 draws for one laser range: each range's line (its label, its points by
    team size), a point past the paper's teams marked `beyond`."""
    out = []
    for comm in sorted({r.comm_range for r in rows if r.laser_range == laser}):
        pts = sorted(
            (r for r in rows if r.laser_range == laser and r.comm_range == comm),
            key=lambda r: r.robots,
        )
        points = [Point(r.robots, r.steps.mean, r.steps.ci_low, r.steps.ci_high, r.steps.n,
                        r.beyond_paper) for r in pts]  # fmt: skip
        out.append((f"range {_fmt(comm)} m", points))
    return out


def fig2_figure(rows: list[Fig2Row], laser: float, label: str, title: str = ""):
    """Fig. 2 for one laser range: each range's line of means, its 95% intervals where a
    point has them, and each point's number of runs; teams past the paper's drawn hollow
    over a shaded band that says so."""
    fig, ax = plt.subplots(figsize=(6, 4))
    bars = False
    lines = fig2_lines(rows, laser)
    for name, points in lines:
        bars |= _line(ax, points, name)
    beyond = [p.x for _, points in lines for p in points if p.beyond]
    if beyond:
        ax.axvspan(PAPER_MAX_TEAM + 0.5, max(beyond) + 0.5, color="0.9", zorder=0,
                   label=BEYOND_PAPER)  # fmt: skip
    ax.set_xlabel("team size (robots)")
    ax.set_ylabel("exploration steps (mean over robots)")
    ax.set_title(title or f"Fig. 2({label}): laser range {_fmt(laser)} m", fontsize=9)
    _team_axis(ax)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7 if beyond else None)
    _note(ax, "bars: 95% interval of the mean; n: runs" if bars
          else "n: runs; one run per point, so no interval")  # fmt: skip
    fig.tight_layout()
    return fig


def plot_fig2(rows: list[Fig2Row], laser: float, stem: Path, label: str) -> list[Path]:
    return save(fig2_figure(rows, laser, label), stem)


def _team_axis(ax) -> None:
    """Team sizes are whole robots: integer ticks only (no 1.25 or 1.5)."""
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))


def _note(ax, text: str) -> None:
    ax.text(0.99, 0.01, text, transform=ax.transAxes, ha="right", va="bottom", fontsize=7,
            color="0.35")  # fmt: skip


@dataclass(frozen=True)
class Point:
    """A point of a line: x, y, the error bar's ends (None: no bar) and its number of runs."""

    x: float
    y: float
    low: float | None
    high: float | None
    n: int
    beyond: bool = False  # past the paper's team sizes: drawn hollow


def _line(ax, pts: list[Point], label: str) -> bool:
    """One line of y against x with error bars from low to high where a point has them and
    they span something, each point labelled with its n. The legend shows the line alone:
    bars that are not drawn get no entry. True when a bar was drawn."""
    xs, ys = [p.x for p in pts], [p.y for p in pts]
    (line,) = ax.plot(xs, ys, marker="o", label=label)
    barred = [(p.x, p.y, p.low, p.high) for p in pts
              if p.low is not None and p.high is not None and p.high > p.low]  # fmt: skip
    if barred:
        err = [[y - lo for _, y, lo, _ in barred], [hi - y for _, y, _, hi in barred]]
        ax.errorbar([x for x, *_ in barred], [y for _, y, *_ in barred], yerr=err, fmt="none",
                    ecolor=line.get_color(), capsize=3)  # fmt: skip
    far = [p for p in pts if p.beyond]
    if far:  # hollow: beyond the paper's range
        ax.plot([p.x for p in far], [p.y for p in far], ls="none", marker="o",
                markerfacecolor="white", markeredgecolor=line.get_color())  # fmt: skip
    ax.margins(x=0.08, y=0.12)  # room for the n labels inside the frame
    for p in pts:
        ax.annotate(f"n={p.n}", (p.x, p.y), textcoords="offset points", xytext=(4, 4),
                    fontsize=7, color=line.get_color())  # fmt: skip
    return bool(barred)


def plot_fig4(rows: list[Fig4Row], stem: Path) -> list[Path]:
    teams = sorted({r.robots for r in rows})
    fig, axes = plt.subplots(len(teams), 1, figsize=(7, 2.2 * len(teams)), squeeze=False)
    colors: dict[str | None, str] = {"timer": "tab:blue", "request": "tab:red"}
    for ax, n, letter in zip(axes[:, 0], teams, "abcdefgh", strict=False):
        pts = [r for r in rows if r.robots == n]
        for cause in sorted({p.plan.cause for p in pts}, key=str):
            sel = [p.plan for p in pts if p.plan.cause == cause]
            ax.scatter(
                [p.step for p in sel],
                [p.interval for p in sel],
                s=10,
                color=colors.get(cause, "tab:gray"),
                label=str(cause),
            )
        ax.axhline(
            PLAN_TIMER_STEPS, color="k", ls="--", lw=1, label=f"{PLAN_TIMER_STEPS}-step timer"
        )
        ax.set_ylabel("interval (steps)")
        run = pts[0].run if pts else ""
        ax.set_title(f"Fig. 4({letter}): {n} robot{'s' if n > 1 else ''} ({run})", fontsize=9)
        ax.legend(fontsize=7, loc="upper right")
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("step of the plan generation")
    fig.tight_layout()
    return save(fig, stem)


def routing_figure(rows: list[RoutingRow]):
    fig, axes = plt.subplots(2, 2, figsize=(9, 6.5))
    for ax, (key, label) in zip(axes.flat, ROUTING_METRICS, strict=True):
        for comm in sorted({r.comm_range for r in rows}):
            pts = sorted(
                (r for r in rows if r.comm_range == comm and r.means.of(key).mean is not None),
                key=lambda r: r.robots,
            )
            if not pts:
                continue
            _spread_line(ax, [(r.robots, r.means.of(key), r.n) for r in pts],
                         f"range {_fmt(comm)} m")  # fmt: skip
        ax.set_xlabel("team size (robots)")
        ax.set_ylabel(label, fontsize=8)
        _team_axis(ax)
        ax.grid(alpha=0.3)
        _legend_or_no_data(ax)
    fig.suptitle("Routing metrics from the captures (Section 2.4); bars: min to max over "
                 "the runs; n: runs")  # fmt: skip
    fig.tight_layout()
    return fig


def plot_routing(rows: list[RoutingRow], stem: Path) -> list[Path]:
    return save(routing_figure(rows), stem)


def _legend_or_no_data(ax) -> None:
    """A panel's legend, or "no data" on it when no run measured its metric (e.g. no
    routing packets to count): an empty legend says nothing and matplotlib warns."""
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7)
    else:
        ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)


def _spread_line(ax, pts: list[tuple[float, MeanRange, int]], label: str) -> None:
    """One line of means against x, with error bars from each point's min to max; `pts`:
    (x, the point's metric, its number of runs), each with a mean."""
    _line(ax, [Point(x, m.mean, m.min, m.max, n) for x, m, n in pts if m.mean is not None], label)


def plot_impairments(rows: list[ImpairmentRow], stem: Path) -> list[Path]:
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.8))
    for ax, key, label in (
        (axes[0], "steps", "exploration steps"),
        (axes[1], "pdf", "packet delivery fraction"),
    ):
        for robots, comm, delay in sorted({(r.robots, r.comm_range, r.delay_ms) for r in rows}):
            pts = sorted(
                (
                    r
                    for r in rows
                    if (r.robots, r.comm_range, r.delay_ms) == (robots, comm, delay)
                    and r.of(key).mean is not None
                ),
                key=lambda r: r.loss_pct,
            )
            if not pts:
                continue
            label = f"{robots} robots, {_fmt(comm)} m, delay {_fmt(delay)} ms"
            _spread_line(ax, [(r.loss_pct, r.of(key), r.n) for r in pts], label)
        ax.set_xlabel("link loss (%)")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        _legend_or_no_data(ax)
    fig.tight_layout()
    return save(fig, stem)
