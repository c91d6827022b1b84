"""`testbed report DIR`: figures plus a Markdown report that checks the paper's claims.

Theory of operation. `testbed.analysis.figures.make_all` draws the figures and returns the
tables of numbers behind them; each claim of the paper's Section 5 is a pure function of those
tables (`verdict_*`) that returns a `Verdict`: holds / partly / does not hold / not enough
data, with the numbers it was decided on. `render` puts the verdicts, the figures and the sweep's
bookkeeping (runs done, excluded, skipped, achieved time scale, captures against the AODV
daemons' own counters) into DIR/report.md, next to DIR/figures/.

How each claim is decided (a *group* is one laser range and communication range, a *point*
one team size of a group; steps are the mean over runs of the exploration steps):

- 5.1 team work beats one robot: in a group with a one-robot point, every larger team needs
  fewer steps than one robot.
- 5.1 steps fall then rise with team size: in a group with at least three team sizes, the
  fewest steps are at a team size strictly between the smallest and the largest, and the rise
  from there to the largest team exceeds the run-to-run noise: the two points' 95% confidence
  intervals (testbed.analysis.stats, Student's t) do not overlap.
- 5.1 a smaller range needs more steps: for each team of two or more and laser range, the
  smallest communication range needs more steps than the largest, beyond the noise in the
  same sense.
- 5.1 a shorter laser needs more steps at the same steps-to-team ratio: for each range and
  team, the shorter laser needs more steps, and the ratio of the two lasers' steps is the same
  across team sizes (coefficient of variation at most RATIO_CV_MAX).
- 5.2 a single robot plans on the timer: at least TIMER_SHARE_MIN of a lone robot's plan
  generations (after its first) have cause "timer".
- 5.2 on-request plan generations grow with team size: the Spearman rank correlation between
  team size and the mean number of on-request generations per run is at least RHO_MIN.

A claim holds when it holds in every group that has the data, partly when in some, and does
not hold when in none.
"""

from __future__ import annotations

import argparse
import json
import logging
import statistics
import sys
from dataclasses import dataclass, field
from pathlib import Path

from testbed.analysis import ablation, figures, htmlreport, protocols, stats
from testbed.errors import UsageError
from topology.jsonfile import read_json

log = logging.getLogger(__name__)

HOLDS, PARTLY, FAILS, NO_DATA = "holds", "partly holds", "does not hold", "not enough data"
RATIO_CV_MAX = 0.15
TIMER_SHARE_MIN = 0.95
RHO_MIN = 0.8
DAEMON_AGREEMENT = 0.01


RULES = (
    "team work beats one robot: in a group with a one-robot point, every larger team needs "
    "fewer steps than one robot;",
    "fall then rise: in a group with three or more team sizes, the fewest steps are at a team "
    "size strictly between the smallest and the largest, and the 95% intervals of that point "
    "and of the largest team do not overlap (the rise exceeds the run-to-run spread);",
    "smaller range: for each team of two or more, the smallest range needs more steps than the "
    "largest and their 95% intervals do not overlap;",
    f"intervals: {stats.METHOD}, over a point's runs; the runs a point would need to resolve a "
    "difference d with run-to-run standard deviation s (5% significance, 80% power): "
    "2 ((1.96 + 0.84) s / d)^2;",
    "shorter laser: the shorter laser needs more steps at every (range, team), and the ratio of "
    f"the two lasers' steps varies across team sizes by at most {RATIO_CV_MAX:.0%} (CV);",
    f"timer: at least {TIMER_SHARE_MIN:.0%} of a lone robot's plan generations after its first "
    "are on the timer;",
    "on request: the mean number of on-request plan generations per run rises with team size "
    f"(Spearman rank correlation at least {RHO_MIN});",
    "a claim holds when it holds in every group with the data, partly when in some, and does "
    "not hold when in none.",
)


@dataclass
class Verdict:
    section: str
    claim: str
    verdict: str
    evidence: list[str] = field(default_factory=list)


def _f(x: float) -> str:
    return f"{x:g}"


def _overall(results: list[bool]) -> str:
    if not results:
        return NO_DATA
    if all(results):
        return HOLDS
    return PARTLY if any(results) else FAILS


def _points(fig2: list[dict]) -> dict[tuple, dict[int, float]]:
    """(laser, range) -> {team size: mean steps}."""
    out: dict[tuple, dict[int, float]] = {}
    for r in fig2:
        out.setdefault((r["laser_range"], r["comm_range"]), {})[r["robots"]] = r["mean"]
    return out


def _rows(fig2: list[dict]) -> dict[tuple, dict[int, dict]]:
    """(laser, range) -> {team size: fig2 row} (mean, interval, spread)."""
    out: dict[tuple, dict[int, dict]] = {}
    for r in fig2:
        out.setdefault((r["laser_range"], r["comm_range"]), {})[r["robots"]] = r
    return out


def _group_name(laser, comm) -> str:
    return f"laser {_f(laser)} m, range {_f(comm)} m"


def verdict_team_beats_one(fig2: list[dict]) -> Verdict:
    v = Verdict(
        "5.1", "Team work beats one robot: every team needs fewer steps than one robot", NO_DATA
    )
    results = []
    for (laser, comm), pts in sorted(_points(fig2).items()):
        if 1 not in pts or len(pts) < 2:
            continue
        teams = {n: s for n, s in pts.items() if n > 1}
        ok = all(s < pts[1] for s in teams.values())
        results.append(ok)
        worst = max(teams, key=teams.get)
        v.evidence.append(
            f"{_group_name(laser, comm)}: 1 robot {pts[1]:.0f} steps; teams of "
            f"{min(teams)}-{max(teams)}: {min(teams.values()):.0f}-{max(teams.values()):.0f} "
            f"(most steps: {worst} robots) -> {'yes' if ok else 'no'}"
        )
    v.verdict = _overall(results)
    return v


def verdict_fall_then_rise(fig2: list[dict]) -> Verdict:
    """Noise-aware: the rise from the fewest steps to the largest team must exceed the spread
    of the runs (their 95% intervals do not overlap; testbed.analysis.ablation.rise)."""
    v = Verdict("5.1", "Exploration steps fall, then rise again as the team grows", NO_DATA)
    results = []
    for (laser, comm), pts in sorted(_rows(fig2).items()):
        if len(pts) < 3:
            continue
        ok, why = ablation.rise(pts)
        results.append(ok)
        note = ""
        if min(pts, key=lambda n: pts[n]["mean"]) == max(pts):
            note = " (the sweep may stop short of the turning point)"
        v.evidence.append(f"{_group_name(laser, comm)}: {why} -> {'yes' if ok else 'no'}{note}")
    v.verdict = _overall(results)
    return v


def verdict_smaller_range(fig2: list[dict]) -> Verdict:
    """Noise-aware: for each laser and team of two or more, the smallest range needs more
    steps than the largest and their 95% intervals do not overlap."""
    v = Verdict("5.1", "A smaller communication range needs more steps", NO_DATA)
    by: dict[tuple, dict[float, dict]] = {}
    for r in fig2:
        if r["robots"] >= 2:
            by.setdefault((r["laser_range"], r["robots"]), {})[r["comm_range"]] = r
    results, within = [], []
    for (laser, robots), pts in sorted(by.items()):
        if len(pts) < 2:
            continue
        small, large = pts[min(pts)], pts[max(pts)]
        a, b = ablation._ci(small), ablation._ci(large)
        ok = small["mean"] > large["mean"] and stats.separated(a, b)
        results.append(ok)
        if small["mean"] > large["mean"] and not ok and a is not None and b is not None:
            within.append(ablation.runs_needed(large, small))
        v.evidence.append(
            f"laser {_f(laser)} m, {robots} robots: range {_f(min(pts))} m "
            f"{small['mean']:.0f} {ablation._interval(a)}, range {_f(max(pts))} m "
            f"{large['mean']:.0f} {ablation._interval(b)} -> {'yes' if ok else 'no'}"
        )
    v.verdict = _overall(results)
    if results:
        head = (
            f"smaller range needs more steps, beyond the noise, in {sum(results)} of "
            f"{len(results)} cases"
        )
        if within:
            need = sorted(n for n in within if n)
            if need:
                head += (f"; {len(within)} more in the same direction but within the noise "
                         f"(resolving them would take {need[len(need) // 2]} runs per point, "
                         "median)")  # fmt: skip
        v.evidence.insert(0, head)
    return v


def verdict_shorter_laser(fig2: list[dict]) -> Verdict:
    v = Verdict(
        "5.1",
        "A shorter laser needs more steps, at the same steps-to-team ratio",
        NO_DATA,
    )
    lasers = sorted({r["laser_range"] for r in fig2})
    if len(lasers) < 2:
        return v
    short, long_ = lasers[0], lasers[-1]
    by: dict[tuple, dict[float, float]] = {}
    for r in fig2:
        by.setdefault((r["comm_range"], r["robots"]), {})[r["laser_range"]] = r["mean"]
    more, ratios_by_range = [], {}
    for (comm, _robots), pts in sorted(by.items()):
        if short in pts and long_ in pts:
            more.append(pts[short] > pts[long_])
            ratios_by_range.setdefault(comm, []).append(pts[short] / pts[long_])
    if not more:
        return v
    same_ratio = []
    v.evidence.append(
        f"laser {_f(short)} m needs more steps than laser {_f(long_)} m in {sum(more)} of "
        f"{len(more)} (range, team) points"
    )
    for comm, ratios in sorted(ratios_by_range.items()):
        if len(ratios) < 2:
            continue
        mean = statistics.fmean(ratios)
        cv = statistics.pstdev(ratios) / mean
        same_ratio.append(cv <= RATIO_CV_MAX)
        v.evidence.append(
            f"range {_f(comm)} m: steps ratio {_f(short)} m / {_f(long_)} m = "
            f"{min(ratios):.2f}-{max(ratios):.2f} over team sizes (mean {mean:.2f}, "
            f"CV {cv:.2f}) -> {'same' if cv <= RATIO_CV_MAX else 'varies'}"
        )
    parts = [_overall(more), _overall(same_ratio) if same_ratio else NO_DATA]
    if parts == [HOLDS, HOLDS]:
        v.verdict = HOLDS
    elif parts[0] == FAILS:
        v.verdict = FAILS
    else:
        v.verdict = PARTLY
        v.evidence.append(f"more steps: {parts[0]}; same ratio across team sizes: {parts[1]}")
    return v


def verdict_single_robot_timer(plans: list[dict]) -> Verdict:
    v = Verdict("5.2", "A single robot generates its plans on the timer", NO_DATA)
    alone = [p for p in plans if p["robots"] == 1]
    timer = sum(p.get("timer", 0) for p in alone)
    total = sum(p.get("timer", 0) + p.get("request", 0) for p in alone)
    if not total:
        return v
    share = timer / total
    v.verdict = HOLDS if share >= TIMER_SHARE_MIN else FAILS
    v.evidence.append(
        f"{len(alone)} one-robot runs: {timer} of {total} plan generations after the first "
        f"were on the timer ({share:.0%}; needed {TIMER_SHARE_MIN:.0%})"
    )
    return v


def spearman(xs: list[float], ys: list[float]) -> float | None:
    """Spearman's rank correlation (average ranks for ties); None when undefined."""

    def ranks(v):
        order = sorted(range(len(v)), key=lambda i: v[i])
        r = [0.0] * len(v)
        i = 0
        while i < len(order):
            j = i
            while j + 1 < len(order) and v[order[j + 1]] == v[order[i]]:
                j += 1
            for k in range(i, j + 1):
                r[order[k]] = (i + j) / 2
            i = j + 1
        return r

    if len(xs) < 2:
        return None
    rx, ry = ranks(xs), ranks(ys)
    mx, my = statistics.fmean(rx), statistics.fmean(ry)
    sx = sum((a - mx) ** 2 for a in rx) ** 0.5
    sy = sum((b - my) ** 2 for b in ry) ** 0.5
    if not sx or not sy:
        return None
    return sum((a - mx) * (b - my) for a, b in zip(rx, ry, strict=True)) / (sx * sy)


def verdict_requests_grow(plans: list[dict]) -> Verdict:
    v = Verdict("5.2", "On-request plan generations grow with team size", NO_DATA)
    by_team: dict[int, list[int]] = {}
    for p in plans:
        by_team.setdefault(p["robots"], []).append(p.get("request", 0))
    if len(by_team) < 2:
        return v
    teams = sorted(by_team)
    means = [statistics.fmean(by_team[n]) for n in teams]
    rho = spearman([float(n) for n in teams], means)
    grows = means[-1] > means[0]
    if rho is None:
        v.verdict = FAILS
    elif rho >= RHO_MIN and grows:
        v.verdict = HOLDS
    elif rho > 0 and grows:
        v.verdict = PARTLY
    else:
        v.verdict = FAILS
    v.evidence.append(
        "on-request generations per run (all robots), by team size: "
        + ", ".join(f"{n}: {m:.1f}" for n, m in zip(teams, means, strict=True))
    )
    v.evidence.append(
        f"Spearman rank correlation {rho:.2f} (needed {RHO_MIN})"
        if rho is not None
        else "rank correlation undefined (no variation)"
    )
    return v


def verdicts(tables: dict) -> list[Verdict]:
    fig2, plans = tables["fig2"], tables["plans"]
    return [
        verdict_team_beats_one(fig2),
        verdict_fall_then_rise(fig2),
        verdict_smaller_range(fig2),
        verdict_shorter_laser(fig2),
        verdict_single_robot_timer(plans),
        verdict_requests_grow(plans),
    ]


# ---------------------------------------------------------------- rendering


def _daemon_section(per_run: list[dict]) -> list[str]:
    diffs = [
        (r["run"], r["daemon_relative_difference"])
        for r in per_run
        if r.get("daemon_relative_difference") is not None
    ]
    if not diffs:
        return ["No run has both captures and AODV daemon counters to compare."]
    worst_run, worst = max(diffs, key=lambda d: d[1])
    within = sum(d <= DAEMON_AGREEMENT for _, d in diffs)
    lines = [
        f"AODV control packets counted in the captures against the daemons' own counters: "
        f"{within} of {len(diffs)} runs agree within {DAEMON_AGREEMENT:.0%}; largest "
        f"difference {worst:.2%} ({worst_run})."
    ]
    drops = [(r["run"], r["capture_dropped_packets"]) for r in per_run
             if r.get("capture_dropped_packets")]  # fmt: skip
    if drops:
        worst_run, worst = max(drops, key=lambda d: d[1])
        lines.append(
            f"Captures of {len(drops)} runs lost packets in the kernel (tcpdump: dropped by "
            f"kernel), {sum(n for _, n in drops)} in all, at most {worst} ({worst_run}); "
            "a difference above is most likely those."
        )
    return lines


def _sweep_section(sweep_dir: Path, runs: list[figures.Run]) -> list[str]:
    lines = []
    state = read_json(sweep_dir / "sweep.json") or {}
    spec = state.get("spec") or {}
    if spec:
        by_team = spec.get("time_scale_by_robots") or {}
        scales = (
            ", ".join(f"{v:g} for {k}" for k, v in by_team.items()) + " robots"
            if by_team
            else spec.get("time_scale")
        )
        lines.append(
            f"Sweep file `{state.get('sweep_file', '?')}`: teams {spec.get('robots')}, ranges "
            f"{spec.get('comm_range')} m, lasers {spec.get('laser_range')} m, loss "
            f"{spec.get('loss_pct')} %, delay {spec.get('delay_ms')} ms, {spec.get('runs')} "
            f"run(s) per point, time scale {scales}, routing "
            f"{spec.get('routing')}."
        )
    planned = state.get("runs") or []
    status: dict[str, int] = {}
    for r in runs:
        status[r.result.get("status", "?")] = status.get(r.result.get("status", "?"), 0) + 1
    lines.append(
        f"Finished runs: {len(runs)}"
        + (f" of {len(planned)} planned" if planned else "")
        + " ("
        + ", ".join(f"{k}: {n}" for k, n in sorted(status.items()))
        + "). Runs that crashed or failed are left out of the figures."
    )
    skipped = [r for r in planned if r.get("status") == "skipped"]
    if skipped:
        lines.append(f"Skipped {len(skipped)} run(s): {skipped[0].get('reason')}.")
    missing = [
        r["id"] for r in planned if r.get("status") not in ("skipped",) and r["id"] not in
        {run.run_id for run in runs}
    ]  # fmt: skip
    if missing:
        lines.append(
            f"Not finished: {len(missing)} run(s) ({', '.join(missing[:5])}"
            f"{' ...' if len(missing) > 5 else ''}); resume the sweep to complete them."
        )
    achieved = [
        r.result.get("time_scale_achieved") / r.result.get("time_scale_requested")
        for r in runs
        if r.result.get("time_scale_achieved") and r.result.get("time_scale_requested")
    ]
    misses = [r.result.get("deadline_miss_fraction") or 0.0 for r in runs]
    if achieved:
        lines.append(
            f"Time scale achieved / requested: {min(achieved):.1%} to {max(achieved):.1%}; "
            f"step deadlines missed: up to {max(misses):.1%} of steps "
            f"({sum(m > 0.01 for m in misses)} run(s) above 1%)."
        )
    in_stalls = sum((r.result.get("host_stalls") or {}).get("deadlines_missed", 0) for r in runs)
    missed = sum(r.result.get("deadlines_missed") or 0 for r in runs)
    if in_stalls:
        ours = [r.result.get("deadline_miss_fraction_outside_stalls") or 0.0 for r in runs]
        stalled = sum((r.result.get("host_stalls") or {}).get("stalled_s", 0.0) for r in runs)
        lines.append(
            f"{in_stalls / missed:.0%} of the missed deadlines fell in host stalls (the world, "
            f"at real-time priority, woke over 2 ms late: {stalled:.0f} s in all), which no "
            f"time scale avoids; outside them, up to {max(ours):.1%} of steps "
            f"({sum(m > 0.01 for m in ours)} run(s) above 1%)."
        )
    lines += _scale_lines(runs, state)
    backoffs = state.get("backoffs") or []
    concurrency = [b for b in backoffs if "jobs" in b or "load_limit" in b]
    if concurrency:
        lines.append(
            f"The sweep lowered its concurrency {len(concurrency)} time(s) because runs "
            f"missed step deadlines (now {state.get('jobs')} job(s) at most)."
        )
    scale = [b for b in backoffs if "time_scale_factor" in b]
    if scale:
        factors = state.get("time_scale_factor") or {}
        lines.append(
            f"The sweep changed a team size's time scale {len(scale)} time(s) as runs missed step "
            "deadlines alone (down) or ran clean (up); the factors it ended with, of the file's "
            "time scale: "
            + (", ".join(f"{v:g} for {k}" for k, v in factors.items()) or "none")
            + "."
        )
    return lines


def _scale_lines(runs: list[figures.Run], state: dict) -> list[str]:
    """Which time scales each team size ran at (a sweep may move them), and what calibration
    found where it ran."""
    by_team: dict[int, dict[float, int]] = {}
    for r in runs:
        ts = r.result.get("time_scale_requested") or r.config.get("time_scale")
        if ts:
            scales = by_team.setdefault(r.config["robots"], {})
            scales[ts] = scales.get(ts, 0) + 1
    lines = []
    if by_team:
        parts = [
            f"{n}: " + ", ".join(f"{ts:g} ({k} run{'s' if k > 1 else ''})"
                                 for ts, k in sorted(sc.items(), reverse=True))
            for n, sc in sorted(by_team.items())
        ]  # fmt: skip
        lines.append("Time scales the runs ran at, per team size: " + "; ".join(parts) + ".")
    cal = state.get("calibration") or {}
    if cal:
        found = [
            f"{n} robots x{c['factor']:g} of the file's scale after {len(c['trials'])} trial(s)"
            for n, c in sorted(cal.items(), key=lambda kv: int(kv[0]))
        ]
        lines.append(
            "Calibrated on this machine (--calibrate: short runs alone, up while clean, down "
            "while late): " + "; ".join(found) + "."
        )
    return lines


def _img(name: str, figdir: Path) -> str | None:
    return f"![{name}](figures/{name}.png)" if (figdir / f"{name}.png").is_file() else None


def render(sweep_dir: Path, made: dict, vs: list[Verdict]) -> str:
    figdir = sweep_dir / "figures"
    tables = made["tables"]
    out = [f"# Sweep report: {sweep_dir.name}", ""]
    out += _sweep_section(sweep_dir, made["runs"]) + [""]
    out += ["## The paper's claims against these runs", ""]
    out += ["| Section | Claim | Verdict |", "|---|---|---|"]
    for v in vs:
        out.append(f"| {v.section} | {v.claim} | **{v.verdict}** |")
    out.append("")
    for v in vs:
        out += [f"### {v.section}: {v.claim} — {v.verdict}", ""]
        out += [f"- {e}" for e in v.evidence] or ["- (no runs with the points this claim needs)"]
        out.append("")
    out += [
        "How the verdicts are decided (steps: mean over runs of each run's exploration "
        "steps; a group: one laser and communication range):",
        "",
    ]
    out += [f"- {rule}" for rule in RULES] + [""]
    out += ablation.section(tables.get("fig2_all", []), tables.get("ablation_thirds", []))
    out += protocols.section(tables.get("protocols", []))
    out += ["## Figures", ""]
    for name, data, caption in (
        ("fig2a", "fig2", "Fig. 2(a): exploration steps against team size, first laser range"),
        ("fig2b", "fig2", "Fig. 2(b): exploration steps against team size, second laser range"),
        ("fig4", "fig4", "Fig. 4: interval between successive plan generations (20-step timer "
         "dashed)"),
        ("routing", "routing", "Routing metrics from the captures against team size"),
        ("impairments", "impairments", "Exploration steps and packet delivery fraction against "
         "link loss"),
    ):  # fmt: skip
        img = _img(name, figdir)
        if img:
            if (figdir / f"{data}.csv").is_file():
                caption += f" (numbers: `figures/{data}.csv`)"
            out += [f"{caption}.", "", img, ""]
    paths = sorted((figdir / "paths").glob("*.png")) if (figdir / "paths").is_dir() else []
    if paths:
        out += [f"Path pictures (Figs. 3 and 5): {len(paths)} in `figures/paths/`, e.g.", ""]
        out += [f"![{p.stem}](figures/paths/{p.name})" for p in paths[:4]] + [""]
    out += ["## Routing (Section 2.4)", ""]
    if tables["routing"]:
        out += [
            "| range (m) | robots | runs | overhead (pkts) | PDF | delay median (ms) | "
            "throughput (kbit/s) |",
            "|---|---|---|---|---|---|---|",
        ]
        for r in tables["routing"]:
            out.append(
                f"| {_f(r['comm_range'])} | {r['robots']} | {r['n']} | "
                f"{_num(r['overhead_packets_mean'], '.3f')} | {_num(r['pdf_mean'], '.3f')} | "
                f"{_num(r['delay_ms_median_mean'], '.2f')} | "
                f"{_num(r['throughput_bps_mean'] and r['throughput_bps_mean'] / 1000, '.1f')} |"
            )
        out.append("")
        out += _daemon_section(tables["routing_runs"]) + [""]
        out += [
            "Delays and throughput are host wall-clock: with time scale K, emulated time runs "
            "K times faster than these numbers' clock.",
            "",
        ]
    else:
        out += ["No run has packet captures (sweep file: `capture = true`).", ""]
    return "\n".join(out)


def _num(x, spec: str) -> str:
    return "–" if x is None else format(x, spec)


def write_report(sweep_dir: str | Path, metrics_of=None) -> tuple[Path, list[Verdict]]:
    sweep_dir = Path(sweep_dir)
    made = figures.make_all(sweep_dir, metrics_of=metrics_of)
    vs = verdicts(made["tables"])
    path = sweep_dir / "report.md"
    text = render(sweep_dir, made, vs) + "\n"
    path.write_text(text)
    htmlreport.write_html(sweep_dir, text)  # the same report as one page, figures inlined
    (sweep_dir / "figures" / "verdicts.json").write_text(
        json.dumps([v.__dict__ for v in vs], indent=1) + "\n"
    )
    return path, vs


# ---------------------------------------------------------------- CLI


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("dir", metavar="DIR", help="a sweep directory (testbed sweep --out DIR)")


def main(args: argparse.Namespace) -> int:
    sweep_dir = Path(args.dir)
    if not (sweep_dir / "runs").is_dir():
        raise UsageError(f"DIR {sweep_dir}: not a sweep directory (no runs/ in it)")
    path, vs = write_report(sweep_dir)
    held = sum(v.verdict == HOLDS for v in vs)
    print(f"{path}: {held} of {len(vs)} claims hold", file=sys.stderr)
    for v in vs:
        print(f"  {v.section} {v.claim}: {v.verdict}", file=sys.stderr)
    return 0


if __name__ == "__main__":  # `python -m testbed.analysis.report` is `testbed report`
    from testbed.cli import main as cli_main

    sys.exit(cli_main(["report", *sys.argv[1:]]))
