"""`testbed sweep --calibrate`: each team size's time scale found on this machine before its
first run, with short runs alone at the file's scale times a factor, up while they run clean
and faithful, down while they miss or are not faithful (testbed.sweep.policy's
calibration_next and calibrated decide; the sweep's schedule keeps what they found).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from testbed.files.resultfile import RunResult
from testbed.sweep import policy as sweeppolicy
from testbed.sweep.file import PlannedRun

CALIBRATION_STEPS = 300  # steps of each --calibrate trial (30 s of robot time)


def calibrate(sweep: Any, todo: list[PlannedRun]) -> None:
    """Find each team size's time scale before its first run (the module docstring);
    `sweep`: the testbed.sweep.runner.Sweep whose runs they are."""
    firsts: dict[int, PlannedRun] = {}
    for run in todo:
        firsts.setdefault(run.config.robots, run)
    for robots, run in sorted(firsts.items()):
        trials: list[tuple[float, float, bool]] = []
        factor = sweeppolicy.calibration_next(trials)
        while factor is not None and sweep.stop_signal is None:
            miss, faithful = trial(sweep, run, factor, len(trials) + 1)
            trials.append((round(factor, 3), miss, faithful))
            factor = sweeppolicy.calibration_next(trials)
        found = sweep.schedule.calibrated(robots, trials)
        scale = run.config.time_scale * found
        sweep.progress.update(0, 0, 0, None, f"calibrated teams of {robots}: time scale "
                              f"{scale:.3g} ({found:.0%} of the file's), {len(trials)} "
                              "trial(s)")  # fmt: skip


def trial(sweep: Any, run: PlannedRun, factor: float, k: int) -> tuple[float, bool]:
    """One calibration run: the fraction of its step deadlines missed outside stalls, and
    whether it was faithful (testbed.run.fidelity; a run without a verdict is)."""
    c = run.config
    config = replace(c, max_steps=CALIBRATION_STEPS, time_scale=round(c.time_scale * factor, 3))
    rdir = sweep.out / "calibration" / f"n{c.robots:02d}-{k}"
    proc, log_file = sweep._spawn(config, rdir, rdir.with_suffix(".log"), f"calibrate {k}")
    proc.wait()
    log_file.close()
    res = RunResult.read(rdir)
    if res is None:  # no result: as bad as can be
        return 1.0, True
    return float(res.deadline_miss_fraction_outside_stalls), res.faithful is not False
