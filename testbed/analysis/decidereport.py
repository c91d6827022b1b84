"""The report's section on the deciding design's stage 2 (docs/guide.md, "Deciding the
paper's claims"): each claim's verdict with its runs, its test and its error rate, beside the
verdict the paper's 3 runs a point gave.

Theory of operation. `testbed report SWEEP_DIR` looks for a plan directory (PLAN's --out:
SWEEP_DIR-stage2 beside it by default, or `--stage2 DIR`); with none, the report is the
single sweep's, unchanged. With one, testbed.analysis.decidesweep.load_decided reads it back
(stage 1's directories as plan.json names them, the plan made again with its options, the
runs each stage-2 file plans) and judges every comparison (testbed.analysis.decide.judge);
`section` renders:

- what ran: stage 1's directories and runs (teams past the paper's ten named: they count
  for the rise alone), stage 2's runs done of those planned, and, while stage 2 is
  unfinished, that its verdicts rest on fewer runs than planned (valid, at less power);
- the design in one paragraph: Welch's test, Holm's correction per claim, the error rate per
  claim and how it splits between the stages, the power planned, the budget;
- a table of the claims: the 3-run verdict (the report's own, above; for the shorter laser
  its "more steps" part, the part decided here), the deciding verdict, **changed** where the
  two differ (as holds / does not hold / partly holds / undecided), the comparisons decided;
- per claim, every comparison stage 2 tested or left open: runs at each stage, difference,
  t and its degrees of freedom, p, Holm-adjusted p, the alpha it was judged at, its verdict
  and its stage-1 verdict where that changed; those decided at stage 1 in one line;
- what the budget left undecided, each comparison with the runs a point it would need;
- while no stage-2 run is done (`make experiment` plans stage 2 and stops), only what ran,
  the design and what the budget leaves: no verdict table, nothing marked changed;
- Fig. 2 again over every run the design read (stage 1, the large teams, stage 2), teams
  past ten marked as beyond the paper's range (testbed.analysis.plots).

A plan directory found beside the sweep but unreadable (stage 1 changed since PLAN, a bad
plan.json) is said in one line and judged on nothing: the report never draws a verdict the
data cannot carry. `decided_doc` is the same verdicts as data (figures/decided.json), which
`testbed compare` sets side by side (testbed.analysis.claimcompare).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from testbed.analysis import decide, plots, verdicts
from testbed.analysis.decide import Decision
from testbed.analysis.decidesweep import Decided, paper_rows
from testbed.analysis.tables import PAPER_MAX_TEAM, Fig2Row
from testbed.files.resultvalues import one_line

# decide's claims by the report's verdict each is set beside
REPORT_CLAIM = {
    "team": verdicts.verdict_team_beats_one([]).claim,
    "rise": verdicts.verdict_fall_then_rise([]).claim,
    "range": verdicts.verdict_smaller_range([]).claim,
    "laser": verdicts.verdict_shorter_laser([]).claim,
}
UNDECIDED = "undecided"


def category(verdict: str) -> str:
    """A verdict as one of holds / does not hold / partly holds / undecided / not enough
    data: the words two verdicts are compared in ("undecided (2 of 5 comparisons)", "too few
    runs to decide" and "undecided: within the run-to-run noise" are all undecided)."""
    if verdict in (verdicts.HOLDS, verdicts.FAILS, verdicts.PARTLY, verdicts.NO_DATA):
        return verdict
    return UNDECIDED


def three_run(key: str, vs: Sequence[verdicts.Verdict], fig2: list[Fig2Row]) -> str:
    """The 3-run verdict a decided claim is set beside: the report's own, but for the
    shorter laser its "more steps" part alone (the part decided here)."""
    if key == "laser":
        return verdicts.laser_more_steps(fig2)
    return next((v.verdict for v in vs if v.claim == REPORT_CLAIM[key]), verdicts.NO_DATA)


def _g(x: float) -> str:
    return f"{x:g}"


def _p(p: float) -> str:
    return decide._p(p)


def _minutes(s: float) -> str:
    m = round(s / 60)
    return f"{m // 60} h {m % 60:02d} min" if m >= 60 else f"{max(m, 1) if s else 0} min"


def _runs_line(d: Decided) -> str:
    teams = sorted({r.config.robots for r in d.stage1.runs})
    far = [n for n in teams if n > PAPER_MAX_TEAM]
    dirs = ", ".join(f"`{one_line(str(x))}`" for x in d.stage1.dirs)
    text = f"Stage 1: {len(d.stage1.runs)} finished runs in {dirs}"
    if far:
        text += (f"; teams of {', '.join(map(str, far))} are beyond the paper's range (1-"
                 f"{PAPER_MAX_TEAM}) and count for the rise alone")  # fmt: skip
    text += ". "
    planned, done = d.plan.total_runs, d.done_runs
    text += (f"Stage 2 (`{one_line(str(d.plan_dir))}`): {done} of {planned} planned runs done "
             f"at {len(d.plan.point_runs)} points")  # fmt: skip
    if d.plan.wall_s:
        text += f" (planned: about {_minutes(d.plan.total_wall_s)} one at a time)"
    if planned and not done:
        text += ("; **stage 2 has not run yet** (`sudo make experiment-decide`, or each "
                 "stage-2 file with `testbed sweep`): no deciding verdict is drawn until it "
                 "has")  # fmt: skip
    elif planned and done < planned:
        text += ("; **stage 2 is not finished**: its verdicts rest on the runs done so far, "
                 "at less than the planned power (the error rate stands, as long as the runs "
                 "are not stopped for what they show)")  # fmt: skip
    return text + "."


def _design_line(d: Decided) -> str:
    p = d.plan
    return (f"The test: {decide.TEST}, per comparison of two points' exploration steps; "
            f"Holm's correction over each claim's comparisons. **Error rate:** for each claim, "
            f"the chance that any of its comparisons gets a verdict the truth does not support "
            f"is at most {p.alpha:g} ({p.alpha1:g} at stage 1 on the paper's runs, "
            f"{p.alpha2:g} at stage 2 on stage-2 runs alone). Power planned: {p.power:.0%} "
            f"for the difference stage 1 saw (at least {decide.MIN_EFFECT:.0%} of the mean). "
            f"Budget: {p.budget}. The rise's pair (the team size with the fewest steps) was "
            f"chosen on stage 1, so its stage-1 p is multiplied by the candidates.")  # fmt: skip


def claims_table(d: Decided, vs: Sequence[verdicts.Verdict], fig2: list[Fig2Row]) -> list[str]:
    out = ["| Claim | 3 runs a point | Deciding runs | Changed | Comparisons decided | "
           "Error rate |", "|---|---|---|---|---|---|"]  # fmt: skip
    for key, text in decide.CLAIMS.items():
        mine = [x for x in d.decisions if x.planned.comparison.claim == key]
        if not mine:
            continue
        before, after = three_run(key, vs, fig2), decide.claim_verdict(mine)
        changed = category(before) != category(after)
        done = sum(x.final != decide.UNDECIDED for x in mine)
        out.append(f"| {text} | {before} | **{after}** | "
                   f"{'**changed**' if changed else 'no'} | {done} of {len(mine)} | "
                   f"at most {d.plan.alpha:g} |")  # fmt: skip
    return out


def _test_cells(x: Decision) -> str:
    t = x.stage2
    if t is None:
        return "– | – | – | – | – | –"
    return (f"{t.runs[0]}+{t.runs[1]} | {t.diff:+.0f} | {t.t:.2f} ({t.df:.1f}) | {_p(t.p)} | "
            f"{_p(t.p_holm)} | {_p(t.alpha)}")  # fmt: skip


def claim_detail(d: Decided, key: str) -> list[str]:
    """One claim's comparisons: those stage 1 decided in one line, the others in a table."""
    mine = [x for x in d.decisions if x.planned.comparison.claim == key]
    first = [x for x in mine if x.planned.decided]
    rest = [x for x in mine if not x.planned.decided]
    out = [f"### {decide.CLAIMS[key]} — {decide.claim_verdict(mine)}", ""]
    if first:
        words = sorted({x.final for x in first})
        worst = max(x.planned.stage1.p_holm for x in first if x.planned.stage1)
        out += [f"- {len(first)} of {len(mine)} comparisons decided at stage 1 (3 runs a "
                f"point): {', '.join(words)}; Holm-adjusted p at most {_p(worst)} against "
                f"alpha {d.plan.alpha1:g}.", ""]  # fmt: skip
    if rest:
        out += [
            "| Comparison | Stage 1 runs | Stage 2 runs | Difference (steps) | t (df) | p | "
            "Holm-adjusted p | alpha | Verdict |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for x in rest:
            s1 = x.planned.stage1
            runs1 = f"{s1.runs[0]}+{s1.runs[1]}" if s1 else "–"
            verdict = f"**{x.final}**"
            if x.changed:
                verdict += f" (changed; stage 1: {x.stage1_verdict})"
            if x.stage2 is None:
                verdict += f"; {x.note}"
            out.append(f"| {x.planned.comparison.where} | {runs1} | {_test_cells(x)} | "
                       f"{verdict} |")  # fmt: skip
        out.append("")
    return out


def left_undecided(d: Decided) -> list[str]:
    """What the budget (or the plan's reach) left undecided, with the runs each needs."""
    left = [x for x in d.decisions if not x.planned.decided and not x.planned.in_budget]
    if not left:
        return ["Nothing was left out of stage 2 by the budget.", ""]
    out = [f"Left undecided by the budget or beyond reach ({len(left)} comparisons):", ""]
    for x in left:
        c, n = x.planned.comparison, x.planned.runs
        need = f"needs {n} runs a point at {_point(c.more)} and {_point(c.fewer)}" if n else (
            x.planned.why)  # fmt: skip
        out.append(f"- {decide.CLAIMS[c.claim]}: {c.where}: {need}")
    return out + [""]


def _point(pt: decide.Point) -> str:
    return f"{pt[2]} robots (laser {_g(pt[0])} m, range {_g(pt[1])} m)"


def fig2_rows(d: Decided) -> list[Fig2Row]:
    """Fig. 2's points over every run the design read: stage 1's, the large teams', stage 2's."""
    return paper_rows([*d.stage1.runs, *d.runs2])


def figures(d: Decided, figdir: Path) -> list[str]:
    """Fig. 2 again over every run the design read, teams past ten marked; its lines."""
    rows = fig2_rows(d)
    out = []
    for laser, letter in zip(sorted({r.laser_range for r in rows}, reverse=True), "abcdefgh",
                             strict=False):  # fmt: skip
        name = f"fig2-decided-{letter}"
        title = f"Fig. 2({letter}) with the deciding runs: laser range {_g(laser)} m"
        plots.save(plots.fig2_figure(rows, laser, letter, title), figdir / name)
        out += [f"{title} (every run: the paper's, the large teams', stage 2's; teams past "
                f"{PAPER_MAX_TEAM} on the shaded band, hollow: beyond the paper's range).", "",
                f"![{name}](figures/{name}.png)", ""]  # fmt: skip
    return out


def section(
    d: Decided | None, error: str | None, vs: Sequence[verdicts.Verdict],
    fig2: list[Fig2Row], figdir: Path | None,
) -> list[str]:  # fmt: skip
    """The report's stage-2 section (nothing without a plan directory)."""
    if d is None and error is None:
        return []
    out = ["## The claims decided (stage 2 of the deciding design)", ""]
    if d is None:
        return out + [f"A plan directory was found but not read: {one_line(str(error))}. No "
                      "verdict is drawn from it.", ""]  # fmt: skip
    out += [_runs_line(d), "", _design_line(d), ""]
    if not_run(d):
        return out + left_undecided(d)
    out += claims_table(d, vs, fig2) + [""]
    out += ["A verdict **changed** where the deciding runs' differs from the one 3 runs a point "
            "gave above (compared as holds, does not hold, partly holds, undecided). The 3-run "
            "verdicts are this sweep's alone; the rise's deciding one includes the large teams "
            "where stage 1 had them.", ""]  # fmt: skip
    for key in decide.CLAIMS:
        if any(x.planned.comparison.claim == key for x in d.decisions):
            out += claim_detail(d, key)
    out += left_undecided(d)
    if figdir is not None:
        out += figures(d, figdir)
    return out


def not_run(d: Decided) -> bool:
    """Stage 2 planned runs and none is done: its verdicts would be stage 1's alone."""
    return d.plan.total_runs > 0 and d.done_runs == 0


def decided_doc(d: Decided) -> dict:
    """The deciding verdicts as data (figures/decided.json; testbed compare's)."""
    claims = {}
    for key, text in decide.CLAIMS.items():
        mine = [x for x in d.decisions if x.planned.comparison.claim == key]
        if mine:
            claims[key] = {
                "claim": text,
                "verdict": decide.claim_verdict(mine),
                "comparisons": {x.planned.comparison.where: x.final for x in mine},
            }
    return {"alpha": d.plan.alpha, "alpha1": d.plan.alpha1, "alpha2": d.plan.alpha2,
            "power": d.plan.power, "planned_runs": d.plan.total_runs, "done_runs": d.done_runs,
            "claims": claims}  # fmt: skip
