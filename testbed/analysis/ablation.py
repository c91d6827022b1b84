"""The ablation: which factor makes big teams slow? Coordination and start placement compared.

Theory of operation. A sweep whose grid varies `coordination` (node.coordination: the paper's
rules read literally, or ours) and `start` (corner, centre, spread) runs every team size of
every group (laser range, communication range) under each *variant*. For each variant and
group, the rise at the large-team end is tested against the noise exactly as the report's
fall-then-rise verdict does (testbed.analysis.stats): the fewest steps must fall at a team
size strictly between the smallest and the largest, and the 95% intervals of that point and
of the largest team must not overlap. A factor *produces a rise* when the rise holds under
one of its levels and not under another, the other factor held fixed.

The paper's Fig. 4(d) (10 robots, 20 m) shows three phases of plan generation: many
generations on request at the start, a stretch on the 20-step timer, and requests rising
again at the end when the team crowds into the last unexplored part. To see them or see
them absent, every run of that point is cut into thirds of its steps and the on-request
generations (all robots) counted per third; the mean over the point's runs is reported per
variant, and `ablation_fig4` plots each variant's first run as the paper's Fig. 4 does.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from testbed.analysis import stats
from testbed.analysis.plots import plt, save
from testbed.analysis.rows import Spread
from testbed.analysis.runs import FinishedRun
from testbed.analysis.tables import Fig2Row, plan_intervals

FIG4_ROBOTS = 10
FIG4_RANGE = 20.0
FIG4_LASER = 2.0


def _name(variant: tuple[str, str]) -> str:
    return f"{variant[0]}, {variant[1]}"


def request_thirds(run: FinishedRun) -> list[int]:
    """On-request plan generations of all robots in each third of the run's steps."""
    steps = max(1, run.steps or 1)
    counts = [0, 0, 0]
    for robot in run.robots:
        for p in robot.plans:
            if p.cause == "request":
                counts[min(2, 3 * p.step // steps)] += 1
    return counts


def _fig4_point(runs: list[FinishedRun], variant: tuple[str, str]) -> list[FinishedRun]:
    return sorted(
        (
            r
            for r in runs
            if r.usable
            and r.unimpaired
            and r.variant == variant
            and r.config.robots == FIG4_ROBOTS
            and r.config.comm_range == FIG4_RANGE
            and r.config.laser_range == FIG4_LASER
        ),
        key=lambda r: r.run_id,
    )


@dataclass(frozen=True)
class ThirdsRow:
    """A run of the Fig. 4(d) point: its on-request plan generations per third of its steps."""

    coordination: str
    start_placement: str
    run: str
    steps: int | None
    request_start: int
    request_middle: int
    request_end: int
    timer: int

    @property
    def variant(self) -> tuple[str, str]:
        return self.coordination, self.start_placement


def request_thirds_rows(runs: list[FinishedRun]) -> list[ThirdsRow]:
    """Per variant, per run of 10 robots at 20 m (laser 2 m): on-request generations per third,
    and the plans on the timer, for the report and ablation_thirds.csv."""
    rows = []
    for variant in sorted({r.variant for r in runs if r.usable}):
        for run in _fig4_point(runs, variant):
            start, middle, end = request_thirds(run)
            timer = sum(p.cause == "timer" for rob in run.robots for p in rob.plans)
            rows.append(ThirdsRow(*variant, run.run_id, run.steps, start, middle, end, timer))
    return rows


def plot_fig4_variants(runs: list[FinishedRun], stem: Path) -> list[Path]:
    """One panel per variant: the first run of 10 robots at 20 m, plan intervals against the
    step, by cause, with the thirds marked and their on-request counts written in."""
    variants = [v for v in sorted({r.variant for r in runs if r.usable}) if _fig4_point(runs, v)]
    if not variants:
        return []
    fig, axes = plt.subplots(len(variants), 1, figsize=(7, 2.2 * len(variants)), squeeze=False)
    colors: dict[str | None, str] = {"timer": "tab:blue", "request": "tab:red"}
    for ax, variant in zip(axes[:, 0], variants, strict=True):
        run = _fig4_point(runs, variant)[0]
        pts = plan_intervals(run)
        for cause in sorted({p.cause for p in pts}, key=str):
            sel = [p for p in pts if p.cause == cause]
            ax.scatter([p.step for p in sel], [p.interval for p in sel], s=8,
                       color=colors.get(cause, "tab:gray"), label=str(cause))  # fmt: skip
        steps = run.steps or 1
        for k in (1, 2):
            ax.axvline(k * steps / 3, color="gray", lw=0.8, ls=":")
        thirds = request_thirds(run)
        ax.set_title(f"{_name(variant)} ({run.run_id}): on request per third "
                     f"{thirds[0]} / {thirds[1]} / {thirds[2]}", fontsize=9)  # fmt: skip
        ax.axhline(20, color="k", ls="--", lw=1)
        ax.set_ylabel("interval (steps)")
        ax.legend(fontsize=7, loc="upper right")
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("step of the plan generation")
    fig.tight_layout()
    return save(fig, stem)


# ---------------------------------------------------------------- the report's section


def rise(pts: dict[int, Fig2Row]) -> tuple[bool, str]:
    """Whether a group's steps fall and then rise beyond the noise (see the module docstring),
    with the words that say why. `pts`: team size -> fig2 row."""
    if len(pts) < 3:
        return False, "fewer than three team sizes"
    best = min(pts, key=lambda n: pts[n].steps.mean)
    lo, hi = min(pts), max(pts)
    if not lo < best < hi:
        return False, f"fewest steps at {best} robots: no rise"
    fewest, largest = pts[best].steps, pts[hi].steps
    a, b = fewest.ci, largest.ci
    size = largest.mean - fewest.mean
    need = runs_needed(fewest, largest)
    words = (f"fewest {fewest.mean:.0f} {_interval(a)} at {best} robots, "
             f"{largest.mean:.0f} {_interval(b)} at {hi}: rise {size:.0f} steps")  # fmt: skip
    if stats.separated(a, b):
        return True, words + ", beyond the noise"
    if a is None or b is None:
        return False, words + ": one run at a point, so its noise is unknown"
    return False, words + (f", within the noise (about {need} runs per point would resolve it)"
                           if need else ", within the noise")  # fmt: skip


def runs_needed(a: Spread, b: Spread) -> int | None:
    """Runs per point that would tell two points' means apart (their sd pooled); None when
    a point has one run (no sd)."""
    if a.std is None or b.std is None:
        return None
    sd = ((a.std**2 + b.std**2) / 2) ** 0.5
    return stats.runs_to_resolve(b.mean - a.mean, sd)


def _interval(ci) -> str:
    return f"[{ci[1]:.0f}, {ci[2]:.0f}]" if ci else "[one run]"


def section(fig2_all: list[Fig2Row], thirds: list[ThirdsRow]) -> list[str]:
    """The report's ablation section (Markdown lines); empty when the sweep has one variant."""
    variants = sorted({r.variant for r in fig2_all})
    if len(variants) < 2:
        return []
    out = ["## Ablation: what makes big teams slow", ""]
    out += [
        "Each variant is a coordination mode (`paper`: the paper's rules read literally; "
        "`ours`: see docs/guide.md) and a start placement. Steps are the mean over runs with "
        f"the 95% interval ({stats.METHOD}). A rise holds in a group when the fewest steps "
        "fall at a team size strictly between the smallest and the largest and the intervals "
        "of that point and the largest team do not overlap.",
        "",
    ]
    rises: dict[tuple, bool] = {}
    groups = sorted({(r.laser_range, r.comm_range) for r in fig2_all}, reverse=True)
    for laser, comm in groups:
        out += [f"### Laser {laser:g} m, range {comm:g} m", ""]
        teams = sorted({r.robots for r in fig2_all
                        if (r.laser_range, r.comm_range) == (laser, comm)})  # fmt: skip
        out += ["| variant | " + " | ".join(str(n) for n in teams) + " | rise |",
                "|---|" + "---|" * (len(teams) + 1)]  # fmt: skip
        notes = []
        for v in variants:
            pts = {r.robots: r for r in fig2_all if r.variant == v
                   and (r.laser_range, r.comm_range) == (laser, comm)}  # fmt: skip
            if not pts:
                continue
            ok, why = rise(pts)
            rises[(v, laser, comm)] = ok
            cells = [f"{pts[n].steps.mean:.0f} {_interval(pts[n].steps.ci)}" if n in pts else "–"
                     for n in teams]  # fmt: skip
            out.append(f"| {_name(v)} | " + " | ".join(cells) + f" | {'yes' if ok else 'no'} |")
            notes.append(f"- {_name(v)}: {why}")
        out += [""] + notes + [""]
    out += _factor_lines(rises) + [""]
    out += _thirds_lines(thirds)
    return out


def _factor_lines(rises: dict[tuple, bool]) -> list[str]:
    """Which factor's levels change whether a rise holds, the other factor held fixed."""
    out = ["### Which factor produces a rise", ""]
    if not any(rises.values()):
        return out + ["No variant shows a rise beyond the noise in any group."]
    for factor, idx in (("coordination", 0), ("start placement", 1)):
        found = []
        for (v, laser, comm), ok in sorted(rises.items()):
            if not ok:
                continue
            for (w, l2, c2), ok2 in sorted(rises.items()):
                same_other = w[1 - idx] == v[1 - idx] and w[idx] != v[idx]
                if (l2, c2) == (laser, comm) and same_other and not ok2:
                    found.append(f"{_name(v)} rises and {_name(w)} does not (laser {laser:g} "
                                 f"m, range {comm:g} m)")  # fmt: skip
        out.append(f"- {factor}: " + ("; ".join(found) if found else "changes nothing alone"))
    return out


def _thirds_lines(rows: list[ThirdsRow]) -> list[str]:
    if not rows:
        return ["No runs of 10 robots at 20 m (laser 2 m): no Fig. 4 phases to count.", ""]
    out = [
        f"### Fig. 4 phases: on-request plan generations per third of the run "
        f"({FIG4_ROBOTS} robots, {FIG4_RANGE:g} m, laser {FIG4_LASER:g} m)",
        "",
        "The paper's Fig. 4(d) has many on-request generations at the start, a stretch on "
        "the timer, and a rise again at the end. Mean over the point's runs (all robots):",
        "",
        "| variant | runs | start | middle | end | on the timer |",
        "|---|---|---|---|---|---|",
    ]
    for v in sorted({r.variant for r in rows}):
        sel = [r for r in rows if r.variant == v]
        start, middle, end, timer = (
            sum(getattr(r, k) for r in sel) / len(sel)
            for k in ("request_start", "request_middle", "request_end", "timer")
        )
        out.append(f"| {_name(v)} | {len(sel)} | {start:.1f} | {middle:.1f} | {end:.1f} | "
                   f"{timer:.0f} |")  # fmt: skip
    return out + ["", "![ablation Fig. 4](figures/ablation_fig4.png)", ""]
