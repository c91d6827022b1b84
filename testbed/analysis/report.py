"""`testbed report DIR`: figures plus a Markdown report that checks the paper's claims.

(For one run's directory, `testbed report RUN_DIR` writes that run's metrics instead:
testbed.analysis.runreport.)

Theory of operation. `testbed.analysis.figures.make_all` draws the figures and returns the
tables of numbers behind them; testbed.analysis.verdicts decides each claim of the paper's
Section 5 on those tables. `render` puts the verdicts, the figures and the sweep's
bookkeeping (testbed.analysis.sweepinfo: runs done, excluded, skipped, achieved time scale)
and the routing metrics (captures against the AODV daemons' own counters) into
DIR/report.md, next to DIR/figures/, and the same text as one page into DIR/report.html.

The deciding design's stage 2 (testbed.analysis.decidereport): when a plan directory is
given (`--stage2 DIR`) or found beside the sweep (DIR-stage2 with a plan.json), a section
after the 3-run verdicts sets each claim's deciding verdict beside them, with its runs, its
test and its error rate, and figures/decided.json holds them as data. Without one the report
is the single sweep's, as it was.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from common.errors import UsageError
from common.jsonfile import write_atomic
from testbed.analysis import (
    ablation,
    decidereport,
    decidesweep,
    figures,
    htmlreport,
    pcapmetrics,
    runreport,
    sweepinfo,
)
from testbed.analysis.figures import Made, Tables
from testbed.analysis.protocols import DAEMON_AGREEMENT
from testbed.analysis.runs import ResultError, load_run
from testbed.analysis.tables import RoutingRow, RoutingRun
from testbed.analysis.verdicts import HOLDS, RULES, Verdict, verdicts
from testbed.files.resultfile import has_result
from testbed.files.resultvalues import one_line

log = logging.getLogger(__name__)


def _f(x: float) -> str:
    return f"{x:g}"


def _daemon_section(per_run: list[RoutingRun]) -> list[str]:
    diffs = [
        (r.run, r.daemon_relative_difference)
        for r in per_run
        if r.daemon_relative_difference is not None
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
    drops = [(r.run, r.capture_dropped_packets) for r in per_run
             if r.capture_dropped_packets]  # fmt: skip
    if drops:
        worst_run, worst = max(drops, key=lambda d: d[1])
        lines.append(
            f"Captures of {len(drops)} runs lost packets in the kernel (tcpdump: dropped by "
            f"kernel), {sum(n for _, n in drops)} in all, at most {worst} ({worst_run}); "
            "a difference above is most likely those."
        )
    return lines


def _img(name: str, figdir: Path) -> str | None:
    return f"![{name}](figures/{name}.png)" if (figdir / f"{name}.png").is_file() else None


def render(sweep_dir: Path, made: Made, vs: list[Verdict], stage2: list[str] | None = None) -> str:
    figdir = sweep_dir / "figures"
    tables = made.tables
    out = [f"# Sweep report: {one_line(sweep_dir.name)}", ""]
    out += sweepinfo.lines(sweep_dir, made.runs) + [""]
    left_out = made.left_out
    if left_out:
        out += [f"**Left out: {len(left_out)} run(s) whose files are not a run's** "
                f"(nothing is drawn from them): {'; '.join(left_out[:3])}"
                f"{'; ...' if len(left_out) > 3 else ''}.", ""]  # fmt: skip
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
    out += stage2 or []
    out += ablation.section(tables.fig2_all, tables.ablation_thirds)
    for study in figures.STUDIES:
        out += study.section(getattr(tables, study.name))
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
    out += _routing_section(tables)
    return "\n".join(out)


def _routing_section(tables: Tables) -> list[str]:
    out = ["## Routing (Section 2.4)", ""]
    if not tables.routing:
        return out + ["No run has packet captures (sweep file: `capture = true`).", ""]
    out += [
        "| range (m) | robots | runs | overhead (pkts) | PDF | delay median (ms, wall) | "
        "delay median (ms, emulated) | throughput (kbit/s, wall) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    rows = tables.routing
    # PDF and delay of rows at different time scales are set side by side only where TCP
    # kept emulated time (testbed.run.fidelity.network_verdict): else their cells are marked.
    mixed = len({s for r in rows for s in r.time_scales}) > 1
    marked = [r for r in rows if mixed and not r.tcp_emulated]
    for r in rows:
        mark = " †" if r in marked else ""
        m = r.means
        kbps = m.throughput_bps.mean and m.throughput_bps.mean / 1000
        out.append(
            f"| {_f(r.comm_range)} | {r.robots} | {r.n} | "
            f"{_num(m.overhead_packets.mean, '.3f')} | {_num(m.pdf.mean, '.3f')}{mark} | "
            f"{_num(m.delay_ms_median.mean, '.3f')} | "
            f"{_num(m.delay_ms_median_emulated.mean, '.3f')}{mark} | "
            f"{_num(kbps, '.1f')} |"
        )
    out += [""] + _daemon_section(tables.routing_runs) + [""]
    out += [
        "Delays and throughput are host wall-clock, as the captures are stamped; with time "
        "scale K, emulated time runs K times faster, so an emulated delay is the wall delay "
        "x K (each run's `routing.json` has both, and says what PDF, segment delivery and the "
        "mean and median delay mean; `testbed report RUN_DIR` sums one run up).",
        "",
        *_tcp_time_note(rows, marked),
    ]
    return out


def _tcp_time_note(rows: list[RoutingRow], marked: list[RoutingRow]) -> list[str]:
    """What the PDF and delay of rows at different time scales can be compared for."""
    if marked:
        which = ", ".join(f"{r.robots} robots at {_f(r.comm_range)} m" for r in marked)
        return [
            f"† Ran dilated without TCP's retransmission timer dilated (the kernel lacks "
            f"`tcp_rto_min_us`, Linux 6.11, or the time scale is past its jiffy; result.json's "
            f"`fidelity.network` says which): {which}. A retransmission there waited K times "
            "longer in emulated time than at time scale 1, so compare their PDF and delay only "
            "with runs at the same time scale; steps, plans and control overhead do not "
            'depend on it (docs/architecture.md, "Invariance for teams").',
            "",
        ]
    if len({s for r in rows for s in r.time_scales}) > 1:
        return [
            "TCP's timers were dilated with each run's time scale (result.json's "
            "`network_timers`); what the kernel cannot dilate (a SYN's first timeout, the "
            "delayed ACK's floor, the millisecond clock of TCP timestamps) and how far PDF and "
            'delay then agree across time scales: docs/architecture.md, "Time dilation and '
            'fidelity".',
            "",
        ]
    return []


def _num(x, spec: str) -> str:
    return "–" if x is None else format(x, spec)


def read_stage2(
    sweep_dir: Path, stage2: Path | None
) -> tuple[decidesweep.Decided | None, str | None]:
    """The deciding design's stage 2 for the report: `stage2` (a plan directory, refused in
    one line when it cannot be read or is not this sweep's), else the one beside the sweep
    (its failure to read as words instead); (None, None) when there is none."""
    plan_dir = stage2 or decidesweep.find_plan(sweep_dir)
    if plan_dir is None:
        return None, None
    try:
        if not (plan_dir / decidesweep.PLAN_NAME).is_file():
            raise UsageError(f"{plan_dir}: no {decidesweep.PLAN_NAME} (not PLAN's --out)")
        decided = decidesweep.load_decided(plan_dir)
        if decided.stage1.dirs[0].resolve() != sweep_dir.resolve():
            raise UsageError(f"{plan_dir}: its plan is of {decided.stage1.dirs[0]}, not of "
                             f"{sweep_dir}")  # fmt: skip
    except (UsageError, ValueError, OSError) as e:
        if stage2 is not None:
            raise UsageError(f"--stage2 {one_line(str(e))}") from None
        return None, str(e)
    return decided, None


def write_report(
    sweep_dir: str | Path, metrics_of=None, unfaithful: bool = False,
    stage2: Path | None = None,
) -> tuple[Path, list[Verdict]]:  # fmt: skip
    sweep_dir = Path(sweep_dir)
    decided, error = read_stage2(sweep_dir, stage2)
    made = figures.make_all(sweep_dir, metrics_of=metrics_of, unfaithful=unfaithful)
    vs = verdicts(made.tables)
    path = sweep_dir / "report.md"
    figdir = sweep_dir / "figures"
    section = decidereport.section(decided, error, vs, made.tables.fig2, figdir)
    if decided is not None and not decidereport.not_run(decided):
        write_atomic(figdir / "decided.json",
                     json.dumps(decidereport.decided_doc(decided), indent=1) + "\n",
                     root=sweep_dir)  # fmt: skip
    else:  # an earlier report's, whose stage 2 is gone: not left to be read as this one's
        for stale in [figdir / "decided.json", *figdir.glob("fig2-decided-*")]:
            stale.unlink(missing_ok=True)
    text = render(sweep_dir, made, vs, section) + "\n"
    write_atomic(path, text)  # never through a link (common.jsonfile)
    htmlreport.write_html(sweep_dir, text)  # the same report as one page, figures inlined
    write_atomic(
        sweep_dir / "figures" / "verdicts.json",
        json.dumps([v.__dict__ for v in vs], indent=1) + "\n",
        root=sweep_dir,
    )
    return path, vs


# ---------------------------------------------------------------- CLI


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "dir",
        metavar="DIR",
        help="a sweep directory (testbed sweep --out DIR): figures, report.md and "
        "report.html; or one run's directory (testbed run --out DIR): its routing.json "
        "(from the captures) and summary.md",
    )
    parser.add_argument(
        "--include-unfaithful",
        action="store_true",
        help="count the runs whose fidelity verdict says time dilation changed them "
        "(result.json's fidelity.ok false); by default they are left out and counted",
    )
    parser.add_argument(
        "--stage2",
        metavar="PLAN_DIR",
        help="the deciding design's plan directory (testbed decide PLAN's "
        "--out, with plan.json and the stage-2 sweeps): the report adds each claim's deciding "
        "verdict; default DIR-stage2 beside DIR when it has a plan.json",
    )


def _sweep_main(sweep_dir: Path, unfaithful: bool = False, stage2: Path | None = None) -> int:
    path, vs = write_report(sweep_dir, unfaithful=unfaithful, stage2=stage2)
    held = sum(v.verdict == HOLDS for v in vs)
    print(f"{one_line(str(path))}: {held} of {len(vs)} claims hold", file=sys.stderr)
    for v in vs:
        print(f"  {v.section} {v.claim}: {v.verdict}", file=sys.stderr)
    decided = sweep_dir / "figures" / "decided.json"
    if decided.is_file():  # written just now, from stage 2
        doc = json.loads(decided.read_text())
        print(f"deciding runs ({doc['done_runs']} of {doc['planned_runs']} of stage 2 done):",
              file=sys.stderr)  # fmt: skip
        for c in doc["claims"].values():
            print(f"  {c['claim']}: {c['verdict']}", file=sys.stderr)
    return 0


def _run_main(run_dir: Path) -> int:
    try:
        run = load_run(run_dir)
    except ResultError as e:
        raise UsageError(f"DIR {e}") from None
    path, metrics = runreport.write(run)
    sys.stdout.write(path.read_text())
    made = [str(path)] + ([str(run_dir / pcapmetrics.CACHE_NAME)] if metrics else [])
    print(f"wrote {one_line(', '.join(made))}", file=sys.stderr)
    return 0


def main(args: argparse.Namespace) -> int:
    d = Path(args.dir)
    if (d / "runs").is_dir():
        stage2 = getattr(args, "stage2", None)
        return _sweep_main(d, getattr(args, "include_unfaithful", False),
                           Path(stage2) if stage2 else None)  # fmt: skip
    if has_result(d):
        return _run_main(d)
    raise UsageError(
        f"DIR {d}: neither a sweep directory (no runs/ in it) nor a finished run's directory "
        "(no result.json)"
    )


if __name__ == "__main__":  # `python -m testbed.analysis.report` is `testbed report`
    from testbed.cli import main as cli_main

    sys.exit(cli_main(["report", *sys.argv[1:]]))
