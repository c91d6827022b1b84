"""The deciding design's sweep directories (testbed.analysis.decide holds the design and its
statistics; docs/guide.md, "Deciding the paper's claims"): a finished sweep read for
planning, stage 2's sweep files written, and the command line
`testbed decide PLAN | JUDGE SWEEP_DIR ...`.

- Reading: stage 1 is the sweep directory and any `--with` directories (sweeps of the same
  design at other team sizes: paper-large-teams.toml), their runs through
  testbed.analysis.runs (result.json's type), the Fig. 2 points the report decides on (the
  main network, messaging and variant), each point's expected wall time from its runs'
  `wall_time_s`, and sweep.json through testbed.files.sweepstate (a stage-1 run's planned
  config at each point is the template of its stage-2 runs).
- Writing: a sweep file holds one `runs` for a product grid, so stage 2 is several files
  (`blocks`: the points of one runs count grouped into grids), each checked by the sweep
  file's own parser (testbed.sweep.file.parse) before it is written, with a base seed
  (stage 1's + STAGE2_SEED, raised while any derived seed would repeat one of stage 1's)
  so that stage 2's runs are fresh draws. Every other option is stage 1's.
- The plan written down: PLAN writes `plan.json` beside stage 2's files (stage 1's
  directories relative to it, alpha, power, the budget, each file's points and runs);
  `load_decided` reads a plan directory back (JUDGE, `testbed report`, `testbed compare`): it
  plans again from stage 1 with the recorded options, refuses a stage 1 that no longer gives
  the recorded plan, and takes from each stage-2 directory (stage2-NN/ beside its file) only
  the runs its file plans, so a stale or foreign run is not judged.
- The command line: bad input (a path that is not a sweep directory, an alpha or power
  outside (0, 1), a wall-time budget without wall times, a sweep.json that is not one) is
  one line on stderr and status 2.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import tomllib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from common import boundedfile
from common.errors import UsageError
from common.jsonfile import write_atomic
from testbed.analysis import middlewares, tables
from testbed.analysis.decide import (
    ALPHA,
    CLAIMS,
    POWER,
    TEST,
    Comparison,
    Decision,
    Plan,
    Point,
    _g,
    _pt,
    claim_verdict,
    comparisons,
    judge,
    plan,
    samples,
)  # fmt: skip
from testbed.analysis.runs import FinishedRun, load_runs
from testbed.analysis.tables import Fig2Row
from testbed.files import sweepstate
from testbed.files.options import GRID, RUN
from testbed.files.resultfile import RESULT_NAME
from testbed.files.runconfig import OPTIONS, RunConfig
from testbed.sweep import file as sweepfile

# ------------------------------------------------------------------ a sweep directory


def paper_rows(runs: list[FinishedRun]) -> list[Fig2Row]:
    """The Fig. 2 points the report's verdicts are decided on: the main network, messaging
    and variant's (as testbed.analysis.figures.make_all selects them)."""
    network = tables.main_network(runs)
    messaging = middlewares.main_messaging(runs)
    runs = [r for r in runs if r.network == network
            and (middlewares.middleware_of(r), middlewares.failure_of(r)) == messaging]  # fmt: skip
    main = tables.main_variant(runs)
    return [r for r in tables.fig2_rows(runs) if r.variant == main]


def wall_times(runs: list[FinishedRun], points: Iterable[Point]) -> dict[Point, float]:
    """The expected wall seconds of a run at each point: the mean `wall_time_s` of its runs,
    else of its team size's, else of all; empty when no run recorded one."""
    by_point: dict[Point, list[float]] = {}
    for r in runs:
        if r.wall_time_s is not None and r.wall_time_s > 0:
            c = r.config
            by_point.setdefault((c.laser_range, c.comm_range, c.robots), []).append(r.wall_time_s)
    every = [w for ws in by_point.values() for w in ws]
    if not every:
        return {}
    out = {}
    for pt in points:
        same = by_point.get(pt) or [w for q, ws in by_point.items() if q[2] == pt[2] for w in ws]
        out[pt] = statistics.fmean(same or every)
    return out


@dataclass
class Stage1:
    """A finished sweep read for planning (with the sweeps of other team sizes, if any)."""

    runs: list[FinishedRun]
    rows: list[Fig2Row]
    comps: list[Comparison] = field(default_factory=list)
    data: dict[Point, tuple[float, ...]] = field(default_factory=dict)
    dirs: tuple[Path, ...] = ()  # the sweep directory first, then the --with ones


def read_stage1(sweep_dir: Path, more: Sequence[Path] = ()) -> Stage1:
    runs: list[FinishedRun] = []
    for d in (sweep_dir, *more):
        if not d.is_dir():
            raise UsageError(f"{d}: not a directory")
        found = load_runs(d)
        if not found:
            raise UsageError(f"{d}: no finished runs (no runs/*/result.json)")
        runs += found
    rows = paper_rows(runs)
    comps = comparisons(rows)
    if not comps:
        raise UsageError(f"{sweep_dir}: no comparison the paper's claims rest on (too few "
                         "points with usable runs)")  # fmt: skip
    return Stage1(runs, rows, comps, samples(rows), (sweep_dir, *more))


# ------------------------------------------------------------------ stage 2's sweep files

STAGE2_SEED = 1_000_003  # added to stage 1's base seed (more while a seed would repeat)
_GRID_ONLY = tuple(o for o in OPTIONS if o.sweep == {GRID})
_RUN_ONLY = tuple(o for o in OPTIONS if RUN in o.sweep and o.name != "time_scale")
_POINT = ("robots", "comm_range", "laser_range")


def blocks(point_runs: dict[Point, int]) -> list[tuple[list[Point], int]]:
    """The points with their runs as grids a sweep file can hold (one `runs` a file, its
    points a product of team sizes, ranges and lasers): points of one runs count grouped by
    (laser, range), then groups of the same team sizes merged over ranges, then lasers."""
    by: dict[tuple, set[int]] = {}
    for (laser, comm, robots), n in point_runs.items():
        by.setdefault((n, laser, comm), set()).add(robots)
    by_comm: dict[tuple, set[float]] = {}
    for (n, laser, comm), teams in by.items():
        by_comm.setdefault((n, laser, tuple(sorted(teams))), set()).add(comm)
    by_laser: dict[tuple, set[float]] = {}
    for (n, laser, teams), comms in by_comm.items():
        by_laser.setdefault((n, teams, tuple(sorted(comms))), set()).add(laser)
    out = []
    for (n, teams, comms), lasers in sorted(by_laser.items()):
        pts = [(la, c, r) for la in sorted(lasers, reverse=True) for c in comms for r in teams]
        out.append((pts, n))
    return out


def _toml(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int | float):
        if not math.isfinite(v):
            raise ValueError(f"{v} has no TOML form in a sweep file")
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)  # a JSON string is a TOML basic string
    raise ValueError(f"{v!r}: not a sweep file value")


def stage2_text(
    pts: list[Point], runs: int, templates: dict[Point, RunConfig], scales: dict[int, float],
    seed: int, title: str,
) -> str:  # fmt: skip
    """A sweep file (testbed.sweep.file's format) of the product grid `pts`, `runs` runs a
    point, every other option as stage 1 ran it (`templates`: a stage-1 run's config at each
    point), each team size's time scale `scales`, and base seed `seed`."""
    t = templates[pts[0]]
    lines = [f"description = {_toml(title)}", "", "[grid]"]
    for name in _POINT:
        values = sorted({getattr(templates[pt], name) for pt in pts},
                        reverse=name == "laser_range")  # fmt: skip
        lines.append(f"{name} = [{', '.join(_toml(v) for v in values)}]")
    for opt in _GRID_ONLY:
        if opt.name not in _POINT and getattr(t, opt.name) != opt.default:
            lines.append(f"{opt.name} = [{_toml(getattr(t, opt.name))}]")
    lines += [f"runs = {runs}", "", "[run]"]
    teams = sorted({pt[2] for pt in pts})
    lines.append("time_scale = { " + ", ".join(f"{n} = {_toml(float(scales[n]))}"
                                              for n in teams) + " }")  # fmt: skip
    for opt in _RUN_ONLY:
        value = getattr(t, opt.name)
        if value is not None and value != opt.default:
            lines.append(f"{opt.name} = {_toml(value)}")
    lines.append(f"seed = {seed}")
    return "\n".join(lines) + "\n"


def _templates(stage1: Stage1, states: Sequence[sweepstate.SweepState], pts: Iterable[Point]):
    """A stage-1 run's config (as its sweep.json planned it) at each point, and each team
    size's time scale as its sweep file set it."""
    ids = {_pt(r): r.runs for r in stage1.rows}
    out: dict[Point, RunConfig] = {}
    scales: dict[int, float] = {}
    for pt in pts:
        found = [(st, run) for rid in ids.get(pt, ()) for st in states
                 if (run := st.run(rid)) is not None and run.config is not None]  # fmt: skip
        if not found:
            raise UsageError(f"sweep.json plans no run of {_point_name(pt)}")
        state, planned = found[0]
        assert planned.config is not None
        out[pt] = t = RunConfig.from_dict(dict(planned.config))
        by_file = state.spec.get("time_scale_by_robots") or {}
        scales[pt[2]] = float(by_file.get(str(pt[2]), t.time_scale))
    return out, scales


def write_stage2(
    p: Plan, stage1: Stage1, sweep_dir: Path, out: Path
) -> list[tuple[Path, list[Point], int]]:
    """Stage 2's sweep files in `out` (stage2-01.toml, ...; one per grid of `blocks`), each
    checked by the sweep file's own parser, their seeds none of stage 1's (of any of its
    directories). Returns (file, points, runs a point) for each."""
    states = []
    for d in stage1.dirs or (sweep_dir,):
        state = sweepstate.read(d)
        if state is None:
            raise UsageError(f"{d}: no sweep.json (not a sweep directory)")
        states.append(state)
    state = states[0]
    templates, scales = _templates(stage1, states, p.point_runs)
    used = {r.config.get("seed") for st in states for r in st.runs if r.config}
    base = state.spec.get("seed") or 0
    base = (base if isinstance(base, int) else 0) + STAGE2_SEED
    grids = blocks(p.point_runs)
    while True:
        texts, seeds = [], []
        for k, (pts, n) in enumerate(grids, start=1):
            title = (f"Stage 2 of deciding the claims of {sweep_dir.name} ({k} of {len(grids)}): "
                     f"{n} runs a point, planned by testbed.analysis.decide")  # fmt: skip
            text = stage2_text(pts, n, templates, scales, base, title)
            spec = sweepfile.parse(tomllib.loads(text), out / f"stage2-{k:02d}.toml")
            seeds += [r.config.seed for r in sweepfile.expand(spec)]
            texts.append(text)
        if not used.intersection(seeds) and len(set(seeds)) == len(seeds):
            break
        base += 1
    if texts:
        out.mkdir(parents=True, exist_ok=True)
    written = []
    for k, (text, (pts, n)) in enumerate(zip(texts, grids, strict=True), start=1):
        path = out / f"stage2-{k:02d}.toml"
        write_atomic(path, text)
        written.append((path, pts, n))
    for old in set(out.glob("stage2-*.toml")) - {w[0] for w in written}:
        old.unlink()  # an earlier plan's: not run by mistake (make experiment-decide)
    return written


# ------------------------------------------------------------------ the plan written down

PLAN_NAME = "plan.json"
PLAN_FORMAT = 1


@dataclass(frozen=True)
class Options:
    """What a plan was made with (PLAN's options, recorded in plan.json)."""

    alpha: float = ALPHA
    power: float = POWER
    budget_runs: int | None = None
    budget_minutes: float | None = None


def write_plan_file(
    out: Path, p: Plan, stage1: Stage1, opts: Options,
    files: Sequence[tuple[Path, list[Point], int]],
) -> Path:  # fmt: skip
    """plan.json in `out`: stage 1's directories (relative to `out`), the options, and each
    stage-2 file's points and runs a point."""
    doc = {
        "format": PLAN_FORMAT,
        "about": "the deciding design's stage 2, planned by testbed decide PLAN",
        "stage1": [os.path.relpath(d.resolve(), out.resolve()) for d in stage1.dirs],
        "alpha": opts.alpha,
        "power": opts.power,
        "budget_runs": opts.budget_runs,
        "budget_minutes": opts.budget_minutes,
        "total_runs": p.total_runs,
        "wall_s": round(p.total_wall_s, 1) if p.wall_s else None,
        "files": [
            {"file": f.name, "runs": n, "points": [list(pt) for pt in pts]} for f, pts, n in files
        ],  # fmt: skip
    }
    out.mkdir(parents=True, exist_ok=True)
    path = out / PLAN_NAME
    write_atomic(path, json.dumps(doc, indent=1) + "\n")
    return path


@dataclass
class Decided:
    """A plan directory read back and judged: stage 1, the plan, stage 2's runs (those its
    files plan), each comparison's decision."""

    plan_dir: Path
    stage1: Stage1
    plan: Plan
    opts: Options
    runs2: list[FinishedRun]
    decisions: list[Decision]

    @property
    def done_runs(self) -> int:
        """Usable stage-2 runs at the planned points."""
        got = samples(paper_rows(self.runs2))
        return sum(min(n, len(got.get(pt, ()))) for pt, n in self.plan.point_runs.items())


def _plan_doc(plan_dir: Path) -> dict:
    path = plan_dir / PLAN_NAME
    try:
        doc = boundedfile.load_json(path, 1 << 20)
    except boundedfile.Refused as e:
        raise UsageError(f"{path}: {boundedfile.describe(e)}") from None
    ok = (isinstance(doc, dict) and doc.get("format") == PLAN_FORMAT
          and isinstance(doc.get("stage1"), list) and doc["stage1"]
          and all(isinstance(d, str) for d in doc["stage1"])
          and isinstance(doc.get("files"), list)
          and all(isinstance(f, dict) and isinstance(f.get("file"), str)
                  and f["file"] == Path(f["file"]).name and f["file"].endswith(".toml")
                  for f in doc["files"]))  # fmt: skip
    if not ok:
        raise UsageError(f"{path}: not a plan of testbed decide (format "
                         f"{PLAN_FORMAT})")  # fmt: skip
    return doc


def _options(doc: dict, path: Path) -> Options:
    def num(key, kind, default):
        v = doc.get(key, default)
        if v is None or (isinstance(v, kind) and not isinstance(v, bool)):
            return v
        raise UsageError(f"{path}: {key}: not a number")

    return Options(num("alpha", float, ALPHA), num("power", float, POWER),
                   num("budget_runs", int, None),
                   num("budget_minutes", int | float, None))  # fmt: skip


def load_decided(plan_dir: Path) -> Decided:
    """A plan directory (PLAN's --out) judged: stage 1 read from the directories plan.json
    names, planned again with its options (refused when that no longer gives its points and
    runs), stage 2's runs from stage2-NN/ beside each file, those the file plans alone."""
    doc = _plan_doc(plan_dir)
    opts = _options(doc, plan_dir / PLAN_NAME)
    dirs = [Path(os.path.normpath(plan_dir / d)) for d in doc["stage1"]]
    stage1 = read_stage1(dirs[0], dirs[1:])
    _checked_options(opts)
    p = make_plan(stage1, opts, dirs[0])
    recorded: dict[Point, int] = {}
    runs2: list[FinishedRun] = []
    for f in doc["files"]:
        for pt in f.get("points") or []:
            recorded[(float(pt[0]), float(pt[1]), int(pt[2]))] = f.get("runs")
        spec = sweepfile.load(plan_dir / f["file"])
        ids = {(r.run_id, r.config.seed) for r in sweepfile.expand(spec)}
        d = plan_dir / Path(f["file"]).stem
        if (d / "runs").is_dir():
            runs2 += [r for r in load_runs(d) if (r.run_id, r.config.seed) in ids]
    if recorded != p.point_runs:
        raise UsageError(f"{plan_dir}: stage 1 ({', '.join(map(str, dirs))}) no longer gives "
                         "this plan (its runs changed since PLAN): plan again")  # fmt: skip
    return Decided(plan_dir, stage1, p, opts, runs2, judge(p, samples(paper_rows(runs2))))


def large_teams(sweep_dir: Path) -> list[Path]:
    """PLAN's stage 1 without --with: the large teams' sweep beside the sweep
    (SWEEP_DIR-large-teams, paper-large-teams.toml's) when it has finished runs."""
    d = sweep_dir.parent / f"{sweep_dir.name}-large-teams"
    return [d] if any(d.glob(f"runs/*/{RESULT_NAME}")) else []


def find_plan(sweep_dir: Path) -> Path | None:
    """The plan directory PLAN writes by default for `sweep_dir` (SWEEP_DIR-stage2 beside
    it), when it holds a plan.json."""
    d = sweep_dir.parent / f"{sweep_dir.name}-stage2"
    return d if (d / PLAN_NAME).is_file() else None


def _minutes(s: float) -> str:
    m = round(s / 60)
    return f"{m // 60} h {m % 60:02d} min" if m >= 60 else f"{max(m, 1) if s else 0} min"


def add_arguments(ap: argparse.ArgumentParser) -> None:
    """`testbed decide`'s arguments (testbed.cli)."""
    ap.description = "Plan (PLAN) or judge (JUDGE) the runs that decide the paper's claims."
    ap.add_argument("action", choices=("PLAN", "JUDGE"))
    ap.add_argument("sweep_dir", type=Path, help="the finished stage-1 sweep directory")
    ap.add_argument(
        "stage2",
        type=Path,
        nargs="*",
        help="JUDGE: the stage-2 sweep directories "
        "(none: the plan in SWEEP_DIR, when it is PLAN's --out, or beside it)",
    )
    ap.add_argument(
        "--with",
        dest="more",
        type=Path,
        action="append",
        default=[],
        metavar="DIR",
        help="PLAN: another stage-1 sweep of the same design at other team sizes "
        "(paper-large-teams.toml), for the rise; repeatable (default: SWEEP_DIR-large-teams "
        "beside it, when it has runs)",
    )
    budget = ap.add_mutually_exclusive_group()
    budget.add_argument("--budget-runs", type=int, metavar="N")
    budget.add_argument("--budget-minutes", type=float, metavar="M")
    ap.add_argument("--power", type=float, default=POWER)
    ap.add_argument("--alpha", type=float, default=ALPHA)
    ap.add_argument("--out", type=Path, help="PLAN: where the stage-2 sweep files go "
                    "(default: SWEEP_DIR-stage2 beside it)")  # fmt: skip


def main(argv: list[str] | argparse.Namespace | None = None) -> int:
    """`testbed decide PLAN | JUDGE ...` (testbed.cli parses and hands over its Namespace;
    tests hand an argv). A bad directory, option or file is one line and status 2."""
    if isinstance(argv, argparse.Namespace):
        args = argv
    else:
        ap = argparse.ArgumentParser(prog="testbed decide")
        add_arguments(ap)
        try:
            args = ap.parse_args(argv)
        except SystemExit as e:
            return int(e.code or 0)
    try:
        return _run(args)
    except (UsageError, ValueError, OSError) as e:
        print(f"decide: {str(e).splitlines()[0] if str(e) else type(e).__name__}",
              file=sys.stderr)  # fmt: skip
        return 2


def _checked_options(o: Options) -> None:
    if not 0 < o.alpha < 1 or not math.isfinite(o.alpha):
        raise UsageError(f"--alpha must be in (0, 1), not {o.alpha}")
    if not 0 < o.power < 1 or not math.isfinite(o.power):
        raise UsageError(f"--power must be in (0, 1), not {o.power}")
    if o.budget_runs is not None and o.budget_runs < 0:
        raise UsageError(f"--budget-runs must be 0 or more, not {o.budget_runs}")
    if o.budget_minutes is not None and not (
        math.isfinite(o.budget_minutes) and o.budget_minutes >= 0
    ):
        raise UsageError(f"--budget-minutes must be 0 or more, not {o.budget_minutes}")


def _options_of(args: argparse.Namespace) -> Options:
    return Options(args.alpha, args.power, args.budget_runs, args.budget_minutes)


def _plan_dir_of(args: argparse.Namespace) -> Path | None:
    """JUDGE without stage-2 directories: SWEEP_DIR is a plan directory, or has one beside."""
    if (args.sweep_dir / PLAN_NAME).is_file():
        return args.sweep_dir
    return find_plan(args.sweep_dir)


def make_plan(stage1: Stage1, opts: Options, where: Path) -> Plan:
    walls = wall_times(stage1.runs, stage1.data)
    if opts.budget_minutes is not None and not walls:
        raise UsageError(f"{where}: no run recorded wall_time_s: use --budget-runs")
    minutes = opts.budget_minutes
    return plan(stage1.comps, stage1.data, alpha=opts.alpha, power=opts.power,
                wall_s=walls or None, budget_runs=opts.budget_runs,
                budget_s=None if minutes is None else minutes * 60)  # fmt: skip


def _run(args: argparse.Namespace) -> int:
    opts = _options_of(args)
    _checked_options(opts)
    if args.action == "PLAN" and args.stage2:
        raise UsageError("PLAN takes one sweep directory (stage 2's are JUDGE's)")
    if args.action == "JUDGE" and not args.stage2:
        plan_dir = _plan_dir_of(args)
        if plan_dir is None:
            raise UsageError("JUDGE needs the stage-2 sweep directories after the stage-1 one, "
                             "or a plan directory (PLAN's --out, with plan.json)")  # fmt: skip
        decided = load_decided(plan_dir)
        print("\n".join(judge_lines(decided.plan, decided.decisions)))
        return 0
    stage1 = read_stage1(args.sweep_dir, args.more or large_teams(args.sweep_dir))
    p = make_plan(stage1, opts, args.sweep_dir)
    if args.action == "PLAN":
        out = args.out or args.sweep_dir.parent / f"{args.sweep_dir.name}-stage2"
        files = write_stage2(p, stage1, args.sweep_dir, out)
        write_plan_file(out, p, stage1, opts, files)
        if len(stage1.dirs) > 1:
            print(f"Stage 1: {', '.join(map(str, stage1.dirs))} (the rise over every team size; "
                  "the other claims over the paper's 1-10)")  # fmt: skip
        print("\n".join(plan_lines(p, files, out)))
        return 0
    runs2 = [r for d in args.stage2 for r in _stage2_runs(d)]
    decisions = judge(p, samples(paper_rows(runs2)))
    print("\n".join(judge_lines(p, decisions)))
    return 0


def _stage2_runs(d: Path) -> list[FinishedRun]:
    if not d.is_dir():
        raise UsageError(f"{d}: not a directory")
    return load_runs(d)


def _point_name(pt: Point) -> str:
    return f"laser {_g(pt[0])} m, range {_g(pt[1])} m, {pt[2]} robot{'s' * (pt[2] != 1)}"


def plan_lines(p: Plan, files: Sequence[tuple[Path, list[Point], int]], out: Path) -> list[str]:
    """The plan on one screen: the design, each stage-2 file's points and why, the wall time,
    and what stays undecided."""
    lines = [
        f"Deciding the claims: {TEST}; Holm's correction per claim; alpha {p.alpha:g} "
        f"(stage 1 {p.alpha1:g}, stage 2 {p.alpha2:g}), power {p.power:.0%}; budget {p.budget}.",
    ]
    for claim, text in CLAIMS.items():
        mine = [x for x in p.items if x.comparison.claim == claim]
        if mine:
            done = sum(x.decided for x in mine)
            kept = sum(x.in_budget for x in mine)
            lines.append(f"- {text}: {len(mine)} comparisons, {done} decided at stage 1, "
                         f"{kept} planned")  # fmt: skip
    why: dict[Point, list[str]] = {}
    for x in p.items:
        if x.in_budget:
            for pt in (x.comparison.more, x.comparison.fewer):
                claims = why.setdefault(pt, [])
                if x.comparison.claim not in claims:
                    claims.append(x.comparison.claim)
    lines.append(f"Stage 2: {p.total_runs} runs at {len(p.point_runs)} points"
                 + (f", about {_minutes(p.total_wall_s)} one at a time" if p.wall_s else "")
                 + ":")  # fmt: skip
    for path, pts, n in files:
        wall = sum(n * p.wall_s.get(pt, 0.0) for pt in pts)
        lines.append(f"  {path.name}: {len(pts)} points x {n} runs"
                     + (f" (~{_minutes(wall)})" if p.wall_s else "") + ": "
                     + "; ".join(f"{_point_name(pt)} [{', '.join(why[pt])}]"
                                 for pt in pts))  # fmt: skip
    left = [x for x in p.items if not x.decided and not x.in_budget]
    if left:
        lines.append(f"Left undecided ({len(left)}):")
        for x in left:
            need = f"needs {x.runs} runs a point" if x.runs else x.why
            lines.append(f"  {x.comparison.claim}: {x.comparison.where}: {need}")
    if files:
        lines.append(f"Run: for f in {out}/stage2-*.toml; do testbed sweep \"$f\" "
                     f"--out {out}/$(basename \"$f\" .toml); done")  # fmt: skip
        lines.append(f"Judge: testbed decide JUDGE {out} (its plan.json "
                     "has the options); testbed report shows the verdicts")  # fmt: skip
    return lines


def judge_lines(p: Plan, decisions: Sequence[Decision]) -> list[str]:
    lines = [f"{TEST}; Holm per claim; alpha {p.alpha:g} per claim (stage 1 {p.alpha1:g}, "
             f"stage 2 {p.alpha2:g}, on stage-2 runs alone)."]  # fmt: skip
    for claim, text in CLAIMS.items():
        mine = [d for d in decisions if d.planned.comparison.claim == claim]
        if not mine:
            continue
        lines.append(f"{text}: {claim_verdict(mine)}")
        for d in mine:
            test = d.test
            said = test.words() if test else d.note
            change = f" (stage 1: {d.stage1_verdict})" if d.changed else ""
            lines.append(f"  {d.planned.comparison.where}: {d.final}{change}; {d.note}; {said}")
    return lines


if __name__ == "__main__":
    sys.exit(main())
