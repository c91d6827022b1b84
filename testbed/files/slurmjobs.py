"""A Slurm sweep's jobs file (DIR/slurm/jobs.json) as one type: `SlurmJobs`, the job arrays
testbed.sweep.slurm submitted for the sweep, which it writes after each submission and reads
to tell queued, failed and never-submitted runs apart.

The document is {"jobs": [...]}, one entry per job array in the order they were submitted:
its Slurm job id, its task list, its team size, the CPUs and minutes each task asked for and
its runs (task i runs the i-th); `to_json()` gives the keys in that order, as the file
always had them. `read` takes the file through the one bounded reader (common.boundedfile)
and checks every entry (an object; `job`, `robots`, `cpus`, `minutes` whole numbers, the job
positive; `list` a string; `runs` a list of run directories' names): a file that fails is a
UsageError of one line naming the file and the key. No file: nothing was submitted.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from common import boundedfile
from common.errors import UsageError
from common.jsonfile import write_json_atomic
from testbed.files.resultvalues import one_line
from testbed.files.sweepstate import RUN_ID

JOBS_DIR = "slurm"
JOBS_NAME = "jobs.json"
_COUNTS = ("robots", "cpus", "minutes")


def jobs_path(out: str | Path) -> Path:
    """Where a sweep directory's jobs file is."""
    return Path(out) / JOBS_DIR / JOBS_NAME


def _whole(where: str, value: Any, low: int) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or value < low:
        raise ValueError(f"{where} is {one_line(repr(value), 40)}, not a whole number >= {low}")
    return value


@dataclass(frozen=True)
class SlurmJob:
    """One job array: Slurm's id, its task list (a file of run ids, one a line), its team
    size, what each task asked for, and its runs (task i runs runs[i - 1])."""

    job: int
    task_list: str  # the file's "list"
    robots: int
    cpus: int
    minutes: int
    runs: tuple[str, ...]

    def to_dict(self) -> dict[str, Any]:
        return {"job": self.job, "list": self.task_list, "robots": self.robots,
                "cpus": self.cpus, "minutes": self.minutes, "runs": list(self.runs)}  # fmt: skip

    @classmethod
    def from_dict(cls, where: str, d: Any) -> SlurmJob:
        """An entry of the file; ValueError naming the key unless it is one."""
        if not isinstance(d, dict):
            raise ValueError(f"{where} is not an object")
        task_list, runs = d.get("list"), d.get("runs")
        if not isinstance(task_list, str):
            raise ValueError(f"{where}.list is not a string")
        if not isinstance(runs, list):
            raise ValueError(f"{where}.runs is not a list")
        for i, rid in enumerate(runs):
            if not isinstance(rid, str) or not RUN_ID.fullmatch(rid):
                raise ValueError(f"{where}.runs[{i}] is {one_line(repr(rid), 60)}, not a run id")
        robots, cpus, minutes = (_whole(f"{where}.{key}", d.get(key), 0) for key in _COUNTS)
        return cls(job=_whole(f"{where}.job", d.get("job"), 1), task_list=task_list,
                   robots=robots, cpus=cpus, minutes=minutes, runs=tuple(runs))  # fmt: skip


@dataclass(frozen=True)
class SlurmJobs:
    """The whole file: the job arrays, in the order they were submitted."""

    jobs: tuple[SlurmJob, ...] = ()

    def to_json(self) -> dict[str, Any]:
        return {"jobs": [j.to_dict() for j in self.jobs]}

    @classmethod
    def from_json(cls, doc: Any) -> SlurmJobs:
        """The file's contents checked; ValueError naming the key otherwise."""
        if not isinstance(doc, dict):
            raise ValueError("not a JSON object")
        jobs = doc.get("jobs", [])
        if not isinstance(jobs, list):
            raise ValueError("jobs is not a list")
        return cls(tuple(SlurmJob.from_dict(f"jobs[{i}]", d) for i, d in enumerate(jobs)))


def read(out: str | Path) -> SlurmJobs:
    """DIR/slurm/jobs.json checked (see the module's docstring); no jobs when there is no
    file; UsageError (one line naming the file and the key) when it is not one."""
    path = jobs_path(out)
    try:
        return SlurmJobs.from_json(boundedfile.load_json(path))
    except boundedfile.Refused as r:
        if r.kind == "missing":
            return SlurmJobs()
        raise UsageError(f"{path}: {boundedfile.describe(r)}") from None
    except ValueError as e:
        raise UsageError(f"{path}: {e}") from None


def write(out: str | Path, jobs: SlurmJobs) -> None:
    """DIR/slurm/jobs.json holds `jobs` (atomically; DIR/slurm/ must exist)."""
    write_json_atomic(jobs_path(out), jobs.to_json())
