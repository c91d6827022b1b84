"""The numbers behind the figures: pure functions of a sweep's runs (`FinishedRun`s).

Theory of operation. Each figure of the report is drawn from one table (a list of flat
dicts) computed here and written next to it as CSV and JSON (`write_table`), so a reader or
a test can check a figure against the runs' own result.json; the report's verdicts are
decided on the same tables. Which runs count is the caller's choice of runs plus
`FinishedRun.usable` and `.unimpaired` (testbed.analysis.runs).

- `fig2_rows`: exploration steps per (variant, laser, range, team size) with each point's
  spread and the 95% interval of its mean (testbed.analysis.stats). A point of one run has
  no spread: its std and interval are empty (None), not 0.
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
import statistics
from collections.abc import Callable
from pathlib import Path

from common.jsonfile import write_atomic
from testbed.analysis import stats
from testbed.analysis.runs import DEFAULT_VARIANT, FinishedRun
from topology.spec import VETH

FIG4_TEAMS = (1, 2, 5, 10)
FIG4_LASER = 2.0
FIG4_RANGE = 20.0
ROUTING_METRICS = (
    ("overhead_packets", "routing overhead (control / all packets)"),
    ("pdf", "packet delivery fraction"),
    ("delay_ms_median", "end-to-end delay, median (ms, wall clock)"),
    ("throughput_bps", "throughput (bit/s, wall clock)"),
)

log = logging.getLogger(__name__)

MetricsOf = Callable[[FinishedRun], "dict | None"]


def plan_intervals(run: FinishedRun) -> list[dict]:
    """Each plan generation after a robot's first: its step, cause and interval."""
    rows = []
    for robot in run.robots_by_number():
        plans = sorted(robot.plans, key=lambda p: p.step)
        for prev, cur in zip(plans, plans[1:], strict=False):
            rows.append(
                {
                    "robot": robot.name,
                    "step": cur.step,
                    "interval": cur.step - prev.step,
                    "cause": cur.cause,
                }
            )
    return rows


def spread(values: list[float]) -> dict:
    """n, mean, min, max, std and the 95% interval of the mean; std and the interval are
    None (an empty cell in the CSV) for one value: one run says nothing about the noise."""
    ci = stats.mean_ci(values)
    return {
        "n": len(values),
        "mean": statistics.fmean(values),
        "min": min(values),
        "max": max(values),
        "std": statistics.stdev(values) if len(values) > 1 else None,
        "ci_low": ci[1] if ci else None,
        "ci_high": ci[2] if ci else None,
    }


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


def fig2_rows(runs: list[FinishedRun]) -> list[dict]:
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
        row = {"coordination": coord, "start_placement": start, "laser_range": laser,
               "comm_range": comm, "robots": robots}  # fmt: skip
        row.update(spread([s for _, s in items]))
        row["steps_per_run"] = [s for _, s in items]
        row["runs"] = [rid for rid, _ in items]
        rows.append(row)
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


def fig4_rows(runs: list[FinishedRun]) -> list[dict]:
    rows = []
    for run in fig4_runs(runs):
        c = run.config
        for r in plan_intervals(run):
            rows.append(
                {
                    "robots": c.robots,
                    "comm_range": c.comm_range,
                    "laser_range": c.laser_range,
                    "run": run.run_id,
                    **r,
                }
            )
    return rows


def plan_cause_rows(runs: list[FinishedRun]) -> list[dict]:
    """Per usable unimpaired run: how many plan generations each cause produced."""
    rows = []
    for run in runs:
        if not (run.usable and run.unimpaired):
            continue
        counts = {"start": 0, "timer": 0, "request": 0}
        for robot in run.robots:
            for p in robot.plans:
                cause = p.cause if p.cause is not None else "other"
                counts[cause] = counts.get(cause, 0) + 1
        c = run.config
        rows.append(
            {
                "run": run.run_id,
                "coordination": run.variant[0],
                "start_placement": run.variant[1],
                "robots": c.robots,
                "comm_range": c.comm_range,
                "laser_range": c.laser_range,
                **counts,
            }
        )
    return rows


def routing_per_run(runs: list[FinishedRun], metrics_of: MetricsOf) -> list[dict]:
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
            "robots": c.robots,
            "comm_range": c.comm_range,
            "laser_range": c.laser_range,
            "loss_pct": c.loss_pct,
            "delay_ms": c.delay_ms,
            "time_scale": run.time_scale_requested or c.time_scale,
            "tcp_emulated": run.tcp_in_emulated_time,  # may PDF and delay meet other scales'
        }
        for key, _ in ROUTING_METRICS:
            row[key] = m.get(key)
        row["delay_ms_median_emulated"] = (m.get("emulated") or {}).get("delay_ms_median")
        row["control_tx_packets"] = m.get("control_tx_packets")
        row["tx_packets"] = m.get("tx_packets")
        cmp = m.get("daemon_comparison") or {}
        row["daemon_tx_packets"] = cmp.get("daemon_tx_packets")
        row["daemon_relative_difference"] = cmp.get("relative_difference")
        row["capture_dropped_packets"] = (m.get("capture_dropped") or {}).get("packets")
        rows.append(row)
    return rows


def aggregate(rows: list[dict], keys: tuple[str, ...], metrics: list[str]) -> list[dict]:
    """Per value of `keys`: n, and each metric's mean, min and max (None when no row has it)."""
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
                s = spread(vals)
                row[f"{m}_mean"], row[f"{m}_min"], row[f"{m}_max"] = s["mean"], s["min"], s["max"]
            else:
                row[f"{m}_mean"] = row[f"{m}_min"] = row[f"{m}_max"] = None
        out.append(row)
    return out


def routing_rows(per_run: list[dict]) -> list[dict]:
    """Routing metrics per (range, team size) over the unimpaired runs, lasers pooled; with
    the time scales they ran at and whether TCP kept emulated time in every one of them."""
    base = [r for r in per_run if not r["loss_pct"] and not r["delay_ms"]]
    metrics = [k for k, _ in ROUTING_METRICS] + ["delay_ms_median_emulated"]
    rows = aggregate(base, ("comm_range", "robots"), metrics)
    for row in rows:
        runs = [r for r in base if (r["comm_range"], r["robots"]) == (row["comm_range"],
                                                                      row["robots"])]  # fmt: skip
        row["time_scales"] = sorted({r["time_scale"] for r in runs if r.get("time_scale")})
        row["tcp_emulated"] = all(r.get("tcp_emulated", True) for r in runs)
    return rows


def impairment_rows(runs: list[FinishedRun], per_run: list[dict]) -> list[dict]:
    """Exploration steps and PDF per (team, range, delay, loss) when the sweep varied loss or
    delay; empty otherwise."""
    usable = [r for r in runs if r.usable]
    if len({(r.config.loss_pct, r.config.delay_ms) for r in usable}) < 2:
        return []
    pdf = {r["run"]: r["pdf"] for r in per_run}
    rows = []
    for run in usable:
        c = run.config
        rows.append(
            {
                "robots": c.robots,
                "comm_range": c.comm_range,
                "delay_ms": c.delay_ms,
                "loss_pct": c.loss_pct,
                "steps": run.exploration_steps,
                "pdf": pdf.get(run.run_id),
            }
        )
    return aggregate(rows, ("robots", "comm_range", "delay_ms", "loss_pct"), ["steps", "pdf"])


def _finite_rows(rows: list[dict], stem: Path) -> list[dict]:
    """rows with every number that is not finite (a NaN mean) as None, each said in the log:
    a table never holds NaN silently, and its JSON stays strict."""
    out = []
    for r in rows:
        bad = [k for k, v in r.items() if isinstance(v, float) and not math.isfinite(v)]
        for k in bad:
            point = {k2: v for k2, v in r.items() if k2 in ("robots", "comm_range")}
            log.warning("%s: %s of %s is %s, not a number: left empty", stem.name, k, point, r[k])
        out.append({k: None if k in bad else v for k, v in r.items()})
    return out


def write_table(rows: list[dict], stem: Path) -> None:
    """rows as stem.csv (lists joined by ';') and stem.json; a number that is not finite is
    written empty, and said (_finite_rows)."""
    rows = _finite_rows(rows, stem)
    write_atomic(stem.with_suffix(".json"), json.dumps(rows, indent=1) + "\n")
    fields: list[str] = []
    for r in rows:
        fields += [k for k in r if k not in fields]
    f = io.StringIO(newline="")
    w = csv.DictWriter(f, fieldnames=fields)
    w.writeheader()
    for r in rows:
        w.writerow({k: ";".join(map(str, v)) if isinstance(v, list) else v for k, v in r.items()})
    write_atomic(stem.with_suffix(".csv"), f.getvalue())
