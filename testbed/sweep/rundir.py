"""The run directory contract between a sweep and its runs: where run R lives, when it is
done, and the `testbed run` command line that makes it.

Run `R` of a sweep in DIR lives in `DIR/runs/R/` and is done iff `DIR/runs/R/result.json`
exists and does not say the run was interrupted: `testbed run` writes that file last and
atomically (docs/run-results.md), so the file system alone says what is finished. The local
runner (testbed.sweep.runner) and the Slurm tasks (testbed.sweep.slurm) both start runs with
`run_argv` and judge them with `is_done`, and neither imports the other.

A run's plan, as `sweep.json` records it (`plan_dict`), holds the options a sweep file sets;
the options added after the first sweeps (`newer`) appear only when not the default, so the
plans of older sweeps read as they were.
"""

from __future__ import annotations

from pathlib import Path

from testbed.files.resultfile import RunResult, has_result
from testbed.files.runconfig import OPTIONS, RunConfig, to_argv

# The options a sweep's plan always names (the rest only when not the default): those of the
# sweep file, and the seed (each run's own, derived from the file's base seed).
PLAN_ALWAYS = frozenset(opt.name for opt in OPTIONS if opt.sweep and not opt.newer) | {"seed"}


def run_dir(out: Path, run_id: str) -> Path:
    return out / "runs" / run_id


def is_done(out: Path, run_id: str) -> bool:
    """A run is done iff its result.json exists (the contract's completion marker) and does
    not say it was interrupted (a run stopped by Ctrl-C keeps what it had, but is redone)."""
    rdir = run_dir(out, run_id)
    if not has_result(rdir):
        return False
    result = RunResult.read(rdir)
    return result is None or result.status != "interrupted"


def plan_dict(config: RunConfig) -> dict:
    """The config as a sweep's plan records it: the sweep's options, the always-named ones
    and those not at their default, in table order (what sweep.json holds)."""
    full = config.to_dict()
    return {
        opt.name: full[opt.name]
        for opt in OPTIONS
        if opt.name in PLAN_ALWAYS or getattr(config, opt.name) != opt.default
    }


def run_argv(prefix: list[str], config: RunConfig | dict, out_dir: Path) -> list[str]:
    """The full command line of one run: `prefix`, then the options that give back `config`
    (a RunConfig, or a plan from sweep.json), then --quiet --out."""
    if isinstance(config, dict):
        config = RunConfig.from_dict(config)
    return [*prefix, *to_argv(config, PLAN_ALWAYS), "--quiet", "--out", str(out_dir)]
