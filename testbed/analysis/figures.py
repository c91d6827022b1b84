"""Figures of a sweep: the paper's Figs. 2 to 5, routing metrics and impairments.

Theory of operation. `load_runs` reads every finished run of a sweep directory (`runs/*/`
with a result.json, see docs/run-results.md). The numbers behind each figure come from pure
functions of those runs (`fig2_rows`, `fig4_rows`, `routing_rows`, `impairment_rows`), which
the report reuses for its verdicts; `make_all` plots them with matplotlib (Agg backend) as
PNG and PDF into `DIR/figures/` and writes each figure's numbers next to it as CSV and JSON, so
a test (or a reader) can check a figure against the runs' own results.

Which runs count: runs whose status is `complete` or `step_cap` (a run that hit the step cap
counts its unfinished robots at the final step, as the contract says). Runs that crashed or
failed are left out and counted by the report. The paper's figures use the unimpaired runs
(loss 0, delay 0); the impairment figures exist when a sweep varies loss or delay.

- Fig. 2(a)/(b): exploration steps of a run (mean over robots of finish_step) against team
  size, one line per communication range; the point is the mean over runs, the error bar its
  95% confidence interval (testbed.analysis.stats: Student's t over the point's runs). (a)
  laser 2 m, (b) laser 1.5 m (or whatever lasers ran). A sweep that varies coordination or
  start placement (an ablation) has its Figs. 2 and 4 drawn for its main variant (`ours` and
  `corner` where it ran, else the first that did); testbed.analysis.ablation shows them all.
- Fig. 4(a)-(d): for teams of 1, 2, 5 and 10 (laser 2 m, range 20 m, first run of the point),
  each plan generation's interval since the same robot's previous one, against the step it
  happened at, by cause, with the 20-step timer as a reference line.
- Figs. 3 and 5: the runs' own path pictures (paths.png), collected under figures/paths/.
- Routing: overhead, packet delivery fraction, end-to-end delay and throughput from the pcaps
  (testbed.analysis.pcapmetrics) against team size, one line per range (all laser ranges pooled).
- Impairments: exploration steps and packet delivery fraction against link loss.
"""

from __future__ import annotations

import csv
import json
import logging
import os
import shutil
import statistics
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import matplotlib

from testbed.analysis import stats

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

log = logging.getLogger(__name__)

USABLE = ("complete", "step_cap")
DEFAULT_VARIANT = ("ours", "corner")  # (coordination, start) of runs that did not say
PLAN_TIMER_STEPS = 20
FIG4_TEAMS = (1, 2, 5, 10)
FIG4_LASER = 2.0
FIG4_RANGE = 20.0
ROUTING_METRICS = (
    ("overhead_packets", "routing overhead (control / all packets)"),
    ("pdf", "packet delivery fraction"),
    ("delay_ms_median", "end-to-end delay, median (ms, wall clock)"),
    ("throughput_bps", "throughput (bit/s, wall clock)"),
)


@dataclass
class Run:
    run_id: str
    path: Path
    result: dict

    @property
    def config(self) -> dict:
        return self.result["config"]

    @property
    def usable(self) -> bool:
        return self.result.get("status") in USABLE

    @property
    def variant(self) -> tuple[str, str]:
        """(coordination, start placement); runs from before these existed used the defaults."""
        c = self.config
        extra = c.get("extra") or {}
        return (
            c.get("coordination", extra.get("coordination", DEFAULT_VARIANT[0])),
            c.get("start", extra.get("start", DEFAULT_VARIANT[1])),
        )

    @property
    def unimpaired(self) -> bool:
        return not self.config.get("loss_pct") and not self.config.get("delay_ms")


def load_runs(sweep_dir: str | Path) -> list[Run]:
    """Every run of the sweep with a readable result.json, sorted by run id."""
    runs = []
    for res in sorted(Path(sweep_dir).glob("runs/*/result.json")):
        try:
            result = json.loads(res.read_text())
            result["config"]["robots"]  # noqa: B018 (a result without a config is unusable)
        except (OSError, ValueError, KeyError, TypeError) as e:
            log.warning("skipping %s: unreadable (%s)", res, e)
            continue
        runs.append(Run(res.parent.name, res.parent, result))
    return runs


def exploration_steps(result: dict) -> float | None:
    """Mean over robots of finish_step; a robot that never finished counts the final step."""
    robots = result.get("robots") or {}
    if not robots:
        return None
    final = result.get("steps")
    values = []
    for r in robots.values():
        step = r.get("finish_step")
        values.append(step if step is not None else final)
    if any(v is None for v in values):
        return None
    return statistics.fmean(values)


def plan_intervals(result: dict) -> list[dict]:
    """Each plan generation after a robot's first: its step, cause and interval."""
    rows = []
    for name, r in sorted((result.get("robots") or {}).items(), key=lambda kv: _robot_no(kv[0])):
        plans = sorted(r.get("plans") or [], key=lambda p: p["step"])
        for prev, cur in zip(plans, plans[1:], strict=False):
            rows.append(
                {
                    "robot": name,
                    "step": cur["step"],
                    "interval": cur["step"] - prev["step"],
                    "cause": cur.get("cause"),
                }
            )
    return rows


def _robot_no(name: str) -> int:
    try:
        return int(name.lstrip("r"))
    except ValueError:
        return 0


def _spread(values: list[float]) -> dict:
    ci = stats.mean_ci(values)
    return {
        "n": len(values),
        "mean": statistics.fmean(values),
        "min": min(values),
        "max": max(values),
        "std": statistics.stdev(values) if len(values) > 1 else 0.0,
        "ci_low": ci[1] if ci else None,
        "ci_high": ci[2] if ci else None,
    }


def main_network(runs: list[Run]) -> tuple[str, str]:
    """(routing, map) the paper's figures are drawn for when a sweep varied them (a protocols
    sweep): AODV on the empty terrain where it ran."""
    from testbed.analysis.protocols import map_name

    present = {(r.config.get("routing", "aodv"), map_name(r.config)) for r in runs if r.usable}
    return ("aodv", "empty") if ("aodv", "empty") in present or not present else min(present)


def main_variant(runs: list[Run]) -> tuple[str, str]:
    """The variant the paper's figures are drawn for: the default where it ran."""
    present = {r.variant for r in runs if r.usable}
    return DEFAULT_VARIANT if DEFAULT_VARIANT in present or not present else min(present)


# ---------------------------------------------------------------- the numbers behind figures


def fig2_rows(runs: list[Run]) -> list[dict]:
    """Exploration steps per (variant, laser, range, team size) over the usable unimpaired
    runs, with the 95% confidence interval of each point's mean."""
    groups: dict[tuple, list[tuple[str, float]]] = {}
    for run in runs:
        if not (run.usable and run.unimpaired):
            continue
        steps = exploration_steps(run.result)
        if steps is None:
            continue
        c = run.config
        key = (*run.variant, c["laser_range"], c["comm_range"], c["robots"])
        groups.setdefault(key, []).append((run.run_id, steps))
    rows = []
    for (coord, start, laser, comm, robots), items in sorted(
        groups.items(), key=lambda kv: (kv[0][:2], -kv[0][2], *kv[0][3:])
    ):
        row = {"coordination": coord, "start_placement": start, "laser_range": laser,
               "comm_range": comm, "robots": robots}  # fmt: skip
        row.update(_spread([s for _, s in items]))
        row["steps_per_run"] = [s for _, s in items]
        row["runs"] = [rid for rid, _ in items]
        rows.append(row)
    return rows


def fig4_runs(runs: list[Run]) -> list[Run]:
    """The runs Fig. 4 shows: one per team size (first run of the point), laser 2 m and range
    20 m where present (else the largest laser and range), teams 1, 2, 5, 10 where present
    (else up to four team sizes that ran)."""
    main = main_variant(runs)
    cands = [r for r in runs if r.usable and r.unimpaired and r.variant == main]
    if not cands:
        return []
    lasers = {r.config["laser_range"] for r in cands}
    laser = FIG4_LASER if FIG4_LASER in lasers else max(lasers)
    cands = [r for r in cands if r.config["laser_range"] == laser]
    ranges = {r.config["comm_range"] for r in cands}
    comm = FIG4_RANGE if FIG4_RANGE in ranges else max(ranges)
    cands = [r for r in cands if r.config["comm_range"] == comm]
    by_team: dict[int, Run] = {}
    for r in sorted(cands, key=lambda r: r.run_id):
        by_team.setdefault(r.config["robots"], r)
    teams = [n for n in FIG4_TEAMS if n in by_team]
    teams += [n for n in sorted(by_team) if n not in teams][: 4 - len(teams)]
    return [by_team[n] for n in sorted(teams)]


def fig4_rows(runs: list[Run]) -> list[dict]:
    rows = []
    for run in fig4_runs(runs):
        c = run.config
        for r in plan_intervals(run.result):
            rows.append(
                {
                    "robots": c["robots"],
                    "comm_range": c["comm_range"],
                    "laser_range": c["laser_range"],
                    "run": run.run_id,
                    **r,
                }
            )
    return rows


def plan_cause_rows(runs: list[Run]) -> list[dict]:
    """Per usable unimpaired run: how many plan generations each cause produced."""
    rows = []
    for run in runs:
        if not (run.usable and run.unimpaired):
            continue
        counts = {"start": 0, "timer": 0, "request": 0}
        for r in (run.result.get("robots") or {}).values():
            for p in r.get("plans") or []:
                counts[p.get("cause", "other")] = counts.get(p.get("cause", "other"), 0) + 1
        c = run.config
        rows.append(
            {
                "run": run.run_id,
                "coordination": run.variant[0],
                "start_placement": run.variant[1],
                "robots": c["robots"],
                "comm_range": c["comm_range"],
                "laser_range": c["laser_range"],
                **counts,
            }
        )
    return rows


def routing_per_run(runs: list[Run], metrics_of) -> list[dict]:
    """One row per usable run that has captures: its routing metrics (metrics_of(run) -> dict)."""
    rows = []
    for run in runs:
        if not run.usable:
            continue
        m = metrics_of(run)
        if not m:
            continue
        c = run.config
        row = {
            "run": run.run_id,
            "robots": c["robots"],
            "comm_range": c["comm_range"],
            "laser_range": c["laser_range"],
            "loss_pct": c.get("loss_pct", 0.0),
            "delay_ms": c.get("delay_ms", 0.0),
        }
        for key, _ in ROUTING_METRICS:
            row[key] = m.get(key)
        row["control_tx_packets"] = m.get("control_tx_packets")
        row["tx_packets"] = m.get("tx_packets")
        cmp = m.get("daemon_comparison") or {}
        row["daemon_tx_packets"] = cmp.get("daemon_tx_packets")
        row["daemon_relative_difference"] = cmp.get("relative_difference")
        row["capture_dropped_packets"] = (m.get("capture_dropped") or {}).get("packets")
        rows.append(row)
    return rows


def _aggregate(rows: list[dict], keys: tuple[str, ...], metrics: list[str]) -> list[dict]:
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault(tuple(r[k] for k in keys), []).append(r)
    out = []
    for key, items in sorted(groups.items()):
        row = dict(zip(keys, key, strict=True))
        row["n"] = len(items)
        for m in metrics:
            vals = [i[m] for i in items if i.get(m) is not None]
            if vals:
                s = _spread(vals)
                row[f"{m}_mean"], row[f"{m}_min"], row[f"{m}_max"] = s["mean"], s["min"], s["max"]
            else:
                row[f"{m}_mean"] = row[f"{m}_min"] = row[f"{m}_max"] = None
        out.append(row)
    return out


def routing_rows(per_run: list[dict]) -> list[dict]:
    """Routing metrics per (range, team size) over the unimpaired runs, lasers pooled."""
    base = [r for r in per_run if not r["loss_pct"] and not r["delay_ms"]]
    return _aggregate(base, ("comm_range", "robots"), [k for k, _ in ROUTING_METRICS])


def impairment_rows(runs: list[Run], per_run: list[dict]) -> list[dict]:
    """Exploration steps and PDF per (team, range, delay, loss) when the sweep varied loss or
    delay; empty otherwise."""
    usable = [r for r in runs if r.usable]
    if len({(r.config.get("loss_pct", 0), r.config.get("delay_ms", 0)) for r in usable}) < 2:
        return []
    pdf = {r["run"]: r["pdf"] for r in per_run}
    rows = []
    for run in usable:
        c = run.config
        rows.append(
            {
                "robots": c["robots"],
                "comm_range": c["comm_range"],
                "delay_ms": c.get("delay_ms", 0.0),
                "loss_pct": c.get("loss_pct", 0.0),
                "steps": exploration_steps(run.result),
                "pdf": pdf.get(run.run_id),
            }
        )
    return _aggregate(rows, ("robots", "comm_range", "delay_ms", "loss_pct"), ["steps", "pdf"])


# ---------------------------------------------------------------- writing


def write_table(rows: list[dict], stem: Path) -> None:
    """rows as stem.csv (lists joined by ';') and stem.json."""
    stem.with_suffix(".json").write_text(json.dumps(rows, indent=1) + "\n")
    fields: list[str] = []
    for r in rows:
        fields += [k for k in r if k not in fields]
    with stem.with_suffix(".csv").open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        for r in rows:
            w.writerow(
                {k: ";".join(map(str, v)) if isinstance(v, list) else v for k, v in r.items()}
            )


def _save(fig, stem: Path) -> list[Path]:
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
    return _save(fig, stem)


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
    return _save(fig, stem)


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
    return _save(fig, stem)


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
    return _save(fig, stem)


def collect_paths(runs: list[Run], dest: Path) -> list[Path]:
    """Copy the path pictures (Figs. 3 and 5) of each point's first usable run."""
    dest.mkdir(parents=True, exist_ok=True)
    seen, out = set(), []
    for run in sorted(runs, key=lambda r: r.run_id):
        c = run.config
        point = (
            c["robots"],
            c["comm_range"],
            c["laser_range"],
            c.get("loss_pct"),
            c.get("delay_ms"),
        )
        src = run.path / "paths.png"
        if not run.usable or point in seen or not src.is_file():
            continue
        seen.add(point)
        shutil.copyfile(src, dest / f"{run.run_id}.png")
        out.append(dest / f"{run.run_id}.png")
    return out


def make_all(sweep_dir: str | Path, metrics_of=None) -> dict:
    """Write every figure the sweep has data for into DIR/figures/; returns what was made:
    {"files": [...], "runs": [...], "tables": {name: rows}}."""
    from testbed.analysis import ablation, pcapmetrics, protocols

    if metrics_of is None:

        def metrics_of(run: Run):
            try:
                return pcapmetrics.run_metrics(run.path)
            except OSError as e:  # tshark missing or a capture unreadable
                log.warning("%s: no routing metrics: %s", run.run_id, e)
                return None

    sweep_dir = Path(sweep_dir)
    figdir = sweep_dir / "figures"
    figdir.mkdir(parents=True, exist_ok=True)
    all_runs = load_runs(sweep_dir)
    # The paper's figures and Section 2.4's table: one routing on one map (a protocols sweep
    # has several; they are compared in their own section below).
    network = main_network(all_runs)
    runs = [
        r for r in all_runs
        if (r.config.get("routing", "aodv"), protocols.map_name(r.config)) == network
    ]  # fmt: skip
    files: list[Path] = []
    tables: dict[str, list[dict]] = {}

    fig2_all = fig2_rows(runs)
    write_table(fig2_all, figdir / "fig2")
    main = main_variant(runs)
    fig2 = [r for r in fig2_all if (r["coordination"], r["start_placement"]) == main]
    tables["fig2"], tables["fig2_all"] = fig2, fig2_all
    lasers = sorted({r["laser_range"] for r in fig2}, reverse=True)
    for laser, letter in zip(lasers, "abcdefgh", strict=False):
        files += plot_fig2(fig2, laser, figdir / f"fig2{letter}", letter)

    fig4 = fig4_rows(runs)
    tables["fig4"] = fig4
    write_table(fig4, figdir / "fig4")
    if fig4:
        files += plot_fig4(fig4, figdir / "fig4")
    plans = plan_cause_rows(runs)
    write_table(plans, figdir / "plans")
    tables["plans"] = [r for r in plans if (r["coordination"], r["start_placement"]) == main]
    if len({r.variant for r in runs if r.usable}) > 1:
        tables["ablation_thirds"] = ablation.request_thirds_rows(runs)
        write_table(tables["ablation_thirds"], figdir / "ablation_thirds")
        files += ablation.plot_fig4_variants(runs, figdir / "ablation_fig4")

    # tshark is the slow part: keep the cores busy with one run's captures each.
    with ThreadPoolExecutor(max_workers=os.cpu_count() or 1) as pool:
        metrics = dict(
            zip((r.run_id for r in all_runs), pool.map(metrics_of, all_runs), strict=True)
        )
    if len({r.config.get("routing", "aodv") for r in all_runs if r.usable}) > 1:
        proto_runs = [
            protocols.run_row(r, exploration_steps(r.result), metrics[r.run_id])
            for r in all_runs
            if r.usable
        ]
        tables["protocols_runs"] = proto_runs
        write_table(proto_runs, figdir / "protocols_runs")
        tables["protocols"] = protocols.point_rows(proto_runs)
        write_table(tables["protocols"], figdir / "protocols")
    per_run = routing_per_run(runs, lambda run: metrics[run.run_id])
    tables["routing_runs"] = per_run
    write_table(per_run, figdir / "routing_runs")
    routing = routing_rows(per_run)
    tables["routing"] = routing
    write_table(routing, figdir / "routing")
    if routing:
        files += plot_routing(routing, figdir / "routing")

    imp = impairment_rows(runs, per_run)
    tables["impairments"] = imp
    if imp:
        write_table(imp, figdir / "impairments")
        files += plot_impairments(imp, figdir / "impairments")

    files += collect_paths(runs, figdir / "paths")
    return {"files": files, "runs": all_runs, "tables": tables}
