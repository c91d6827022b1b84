"""Drawing the figures (matplotlib, Agg backend): each plot takes a table of
testbed.analysis.tables and writes PNG and PDF files; nothing here reads a run.

Fig. 2 draws each point's mean with its 95% interval as an error bar; the routing and
impairment figures draw min-to-max bars over the point's runs. Fig. 4 scatters each plan
generation's interval against its step, by cause, with the 20-step timer dashed.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

from testbed.analysis.tables import ROUTING_METRICS

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

PLAN_TIMER_STEPS = 20


def save(fig, stem: Path) -> list[Path]:
    out = [stem.with_suffix(".png"), stem.with_suffix(".pdf")]
    fig.savefig(out[0], dpi=120)
    fig.savefig(out[1])
    plt.close(fig)
    return out


def _fmt(x: float) -> str:
    return f"{x:g}"


def plot_fig2(rows: list[dict], laser: float, stem: Path, label: str) -> list[Path]:
    fig, ax = plt.subplots(figsize=(6, 4))
    for comm in sorted({r["comm_range"] for r in rows if r["laser_range"] == laser}):
        pts = sorted(
            (r for r in rows if r["laser_range"] == laser and r["comm_range"] == comm),
            key=lambda r: r["robots"],
        )
        x = [p["robots"] for p in pts]
        y = [p["mean"] for p in pts]
        # The 95% interval of the mean (none for a point of one run).
        err = [
            [p["mean"] - p["ci_low"] if p["ci_low"] is not None else 0.0 for p in pts],
            [p["ci_high"] - p["mean"] if p["ci_high"] is not None else 0.0 for p in pts],
        ]
        ax.errorbar(x, y, yerr=err, marker="o", capsize=3, label=f"range {_fmt(comm)} m")
    ax.set_xlabel("team size (robots)")
    ax.set_ylabel("exploration steps (mean over robots)")
    ax.set_title(f"Fig. 2({label}): laser range {_fmt(laser)} m")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    return save(fig, stem)


def plot_fig4(rows: list[dict], stem: Path) -> list[Path]:
    teams = sorted({r["robots"] for r in rows})
    fig, axes = plt.subplots(len(teams), 1, figsize=(7, 2.2 * len(teams)), squeeze=False)
    colors = {"timer": "tab:blue", "request": "tab:red"}
    for ax, n, letter in zip(axes[:, 0], teams, "abcdefgh", strict=False):
        pts = [r for r in rows if r["robots"] == n]
        for cause in sorted({p["cause"] for p in pts}, key=str):
            sel = [p for p in pts if p["cause"] == cause]
            ax.scatter(
                [p["step"] for p in sel],
                [p["interval"] for p in sel],
                s=10,
                color=colors.get(cause, "tab:gray"),
                label=str(cause),
            )
        ax.axhline(
            PLAN_TIMER_STEPS, color="k", ls="--", lw=1, label=f"{PLAN_TIMER_STEPS}-step timer"
        )
        ax.set_ylabel("interval (steps)")
        run = pts[0]["run"] if pts else ""
        ax.set_title(f"Fig. 4({letter}): {n} robot{'s' if n > 1 else ''} ({run})", fontsize=9)
        ax.legend(fontsize=7, loc="upper right")
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("step of the plan generation")
    fig.tight_layout()
    return save(fig, stem)


def plot_routing(rows: list[dict], stem: Path) -> list[Path]:
    fig, axes = plt.subplots(2, 2, figsize=(9, 6.5))
    for ax, (key, label) in zip(axes.flat, ROUTING_METRICS, strict=True):
        for comm in sorted({r["comm_range"] for r in rows}):
            pts = sorted(
                (r for r in rows if r["comm_range"] == comm and r[f"{key}_mean"] is not None),
                key=lambda r: r["robots"],
            )
            if not pts:
                continue
            _spread_line(ax, pts, "robots", key, f"range {_fmt(comm)} m")
        ax.set_xlabel("team size (robots)")
        ax.set_ylabel(label, fontsize=8)
        ax.grid(alpha=0.3)
        _legend_or_no_data(ax)
    fig.suptitle("Routing metrics from the captures (Section 2.4)")
    fig.tight_layout()
    return save(fig, stem)


def _legend_or_no_data(ax) -> None:
    """A panel's legend, or "no data" on it when no run measured its metric (e.g. no
    routing packets to count): an empty legend says nothing and matplotlib warns."""
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7)
    else:
        ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)


def _spread_line(ax, pts: list[dict], x: str, key: str, label: str) -> None:
    """One line of means against `x`, with error bars from each point's min to max."""
    err = [
        [p[f"{key}_mean"] - p[f"{key}_min"] for p in pts],
        [p[f"{key}_max"] - p[f"{key}_mean"] for p in pts],
    ]
    ax.errorbar([p[x] for p in pts], [p[f"{key}_mean"] for p in pts], yerr=err, marker="o",
                capsize=3, label=label)  # fmt: skip


def plot_impairments(rows: list[dict], stem: Path) -> list[Path]:
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.8))
    for ax, key, label in (
        (axes[0], "steps", "exploration steps"),
        (axes[1], "pdf", "packet delivery fraction"),
    ):
        for robots, comm, delay in sorted(
            {(r["robots"], r["comm_range"], r["delay_ms"]) for r in rows}
        ):
            pts = sorted(
                (
                    r
                    for r in rows
                    if (r["robots"], r["comm_range"], r["delay_ms"]) == (robots, comm, delay)
                    and r[f"{key}_mean"] is not None
                ),
                key=lambda r: r["loss_pct"],
            )
            if not pts:
                continue
            label = f"{robots} robots, {_fmt(comm)} m, delay {_fmt(delay)} ms"
            _spread_line(ax, pts, "loss_pct", key, label)
        ax.set_xlabel("link loss (%)")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        _legend_or_no_data(ax)
    fig.tight_layout()
    return save(fig, stem)
