"""The report's opening lines: what a sweep ran and how well the host kept up.

Theory of operation. `lines(sweep_dir, runs)` reads the sweep's bookkeeping (sweep.json,
written by `testbed sweep`) and its finished runs (testbed.analysis.runs) and says, one
sentence each: what the sweep file asked for; how many runs finished, by status, and which
were skipped or are still to do; the time scale achieved against the one requested and the
step deadlines missed, with the share of those that fell in host stalls; the time scales
each team size ran at (a sweep may move them, and calibration may have chosen them); and
the sweep's own back-offs (lower concurrency, a changed time scale).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from testbed.analysis.runs import FinishedRun
from testbed.files import sweepstate
from testbed.files.sweepstate import SweepRun, SweepState


def seconds(x: float) -> str:
    """Seconds to two significant digits below 10 s (0.076, 1.2), whole seconds above: a
    short stall is not "0 s"."""
    return f"{x:.2g}" if abs(x) < 10 else f"{x:.0f}"


def lines(sweep_dir: Path, runs: list[FinishedRun]) -> list[str]:
    """The section's sentences (Markdown paragraphs)."""
    state = sweepstate.read(sweep_dir) or sweepstate.SweepState(format=None)
    out = _spec_lines(state)
    out += _finished_lines(runs, state.runs)
    out += _timing_lines(runs)
    out += _scale_lines(runs, state)
    out += _backoff_lines(state)
    return out


def _spec_lines(state: sweepstate.SweepState) -> list[str]:
    spec = state.spec
    if not spec:
        return []
    by_team = spec.get("time_scale_by_robots") or {}
    scales = (
        ", ".join(f"{v:g} for {k}" for k, v in by_team.items()) + " robots"
        if by_team
        else state.spec_value("time_scale")
    )
    teams, ranges, lasers, loss, delay = (state.spec_value(k, listed=True) for k in
                                          ("robots", "comm_range", "laser_range", "loss_pct",
                                           "delay_ms"))  # fmt: skip
    made_by = "?" if state.sweep_file is None else state.sweep_file
    return [
        f"Sweep file `{made_by}`: teams {teams}, ranges {ranges} m, "
        f"lasers {lasers} m, loss {loss} %, delay {delay} ms, {spec.get('runs')} run(s) per "
        f"point, time scale {scales}, routing {state.spec_value('routing')}."
    ]


def _finished_lines(runs: list[FinishedRun], planned: Sequence[SweepRun]) -> list[str]:
    status: dict[str, int] = {}
    for r in runs:
        status[r.status] = status.get(r.status, 0) + 1
    out = [
        f"Finished runs: {len(runs)}"
        + (f" of {len(planned)} planned" if planned else "")
        + " ("
        + ", ".join(f"{k}: {n}" for k, n in sorted(status.items()))
        + "). Runs that crashed or failed are left out of the figures."
    ]
    out += _fidelity_lines(runs)
    skipped = [r for r in planned if r.status == "skipped"]
    if skipped:
        out.append(f"Skipped {len(skipped)} run(s): {skipped[0].reason}.")
    done = {run.run_id for run in runs}
    missing = [r.id for r in planned if r.status != "skipped" and r.id not in done]
    if missing:
        out.append(
            f"Not finished: {len(missing)} run(s) ({', '.join(missing[:5])}"
            f"{' ...' if len(missing) > 5 else ''}); resume the sweep to complete them."
        )
    return out


def _fidelity_lines(runs: list[FinishedRun]) -> list[str]:
    """The runs whose fidelity verdict (testbed.run.fidelity) says time dilation changed them."""
    bad = [r for r in runs if r.faithful is False]
    if not bad:
        return []
    counted = bad[0].count_unfaithful
    shown = "; ".join(f"{r.run_id} at time scale {r.time_scale_requested or r.config.time_scale:g}"
                      f" ({r.fidelity_reason})" for r in bad[:5])  # fmt: skip
    more = f"; and {len(bad) - 5} more" if len(bad) > 5 else ""
    how = (
        "counted nevertheless (--include-unfaithful)"
        if counted
        else "left out of the figures and verdicts (--include-unfaithful counts them)"
    )
    return [
        f"**Not faithful to their time scale: {len(bad)} run(s)**, {how}: work of a step came "
        f"late in emulated time, which changes what the robots do: {shown}{more}."
    ]


def _timing_lines(runs: list[FinishedRun]) -> list[str]:
    """The time scale achieved and the deadlines missed, in and outside host stalls."""
    out = []
    achieved = [
        r.time_scale_achieved / r.time_scale_requested
        for r in runs
        if r.time_scale_achieved and r.time_scale_requested
    ]
    misses = [r.deadline_miss_fraction for r in runs]
    if achieved:
        out.append(
            f"Time scale achieved / requested: {min(achieved):.1%} to {max(achieved):.1%}; "
            f"step deadlines missed: up to {max(misses):.1%} of steps "
            f"({sum(m > 0.01 for m in misses)} run(s) above 1%)."
        )
    in_stalls = sum(r.host_stalls.deadlines_missed for r in runs)
    missed = sum(r.deadlines_missed for r in runs)
    if in_stalls:
        ours = [r.deadline_miss_fraction_outside_stalls for r in runs]
        stalled = sum(r.host_stalls.stalled_s for r in runs)
        out.append(
            f"{in_stalls / missed:.0%} of the missed deadlines fell in host stalls (the world, "
            f"at real-time priority, woke over 2 ms late: {seconds(stalled)} s in all), which no "
            f"time scale avoids; outside them, up to {max(ours):.1%} of steps "
            f"({sum(m > 0.01 for m in ours)} run(s) above 1%)."
        )
    return out


def _scale_lines(runs: list[FinishedRun], state: SweepState) -> list[str]:
    """Which time scales each team size ran at (a sweep may move them), and what calibration
    found where it ran."""
    by_team: dict[int, dict[float, int]] = {}
    for r in runs:
        ts = r.time_scale_requested or r.config.time_scale
        if ts:
            scales = by_team.setdefault(r.config.robots, {})
            scales[ts] = scales.get(ts, 0) + 1
    out = []
    if by_team:
        parts = [
            f"{n}: " + ", ".join(f"{ts:g} ({k} run{'s' if k > 1 else ''})"
                                 for ts, k in sorted(sc.items(), reverse=True))
            for n, sc in sorted(by_team.items())
        ]  # fmt: skip
        out.append("Time scales the runs ran at, per team size: " + "; ".join(parts) + ".")
    cal = state.calibration
    if cal:
        found = [
            f"{n} robots x{c['factor']:g} of the file's scale after {len(c['trials'])} trial(s)"
            for n, c in sorted(cal.items(), key=lambda kv: int(kv[0]))
        ]
        out.append(
            "Calibrated on this machine (--calibrate: short runs alone, up while clean and "
            "faithful, down while late or not faithful): " + "; ".join(found) + "."
        )
    return out


def _backoff_lines(state: SweepState) -> list[str]:
    """What the sweep changed as runs missed deadlines: its concurrency, its time scales."""
    out = []
    backoffs = state.backoffs
    concurrency = [b for b in backoffs if {"jobs", "load_limit", "cpu_limit"} & set(b)]
    if concurrency:
        now = f"{state.jobs} job(s) at most"
        cpu_limit = state.cpu_limit
        if isinstance(cpu_limit, int | float) and not isinstance(cpu_limit, bool):
            now += f", within {cpu_limit:g} cores"
        out.append(
            f"The sweep lowered its concurrency {len(concurrency)} time(s) because runs "
            f"missed step deadlines or were not faithful (now {now})."
        )
    scale = [b for b in backoffs if "time_scale_factor" in b]
    if scale:
        factors = state.time_scale_factor
        out.append(
            f"The sweep changed a team size's time scale {len(scale)} time(s) as runs missed step "
            "deadlines or were not faithful alone (down) or ran clean (up); the factors it ended "
            "with, of the file's time scale: "
            + (", ".join(f"{v:g} for {k}" for k, v in factors.items()) or "none")
            + "."
        )
    return out
