"""robots/rK.json as one type: `RobotStats`, robot K's fuller record of a run, which
testbed.run.results writes (`write`) and the benchmarks read (`read`).

The record is robot K's entry of result.json (testbed.files.resultfile.RobotResult: name, finish,
plans, messages sent and received, ...) with what only this file keeps: its crash step, its
missed deadlines, collisions, final pose, every plan's details, and the keys of its summary
event (node.events; the C++ robot writes the same) that results.SUMMARY_KEYS names (CPU
seconds, peak memory, latencies, CPU per thread, ...), None where the robot left none. The
keys stay in the order they were written, so `to_dict()` is the file.

`read` takes the file through the one bounded reader (common.boundedfile; JSON as the
writer wrote it: a plan's cost may be Infinity) and checks what
its readers use: an object; `cpu_s` and `max_rss_mb` numbers or None; `latency_ms` an object
or None; `thread_cpu_s` an object of numbers or None. A file that is missing, not a regular
file, not JSON or not such an object is None (a benchmark carries on past a robot without a
record), as before the type.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

from common import boundedfile
from common.jsonfile import write_json_atomic
from testbed.files.layout import ROBOTS_DIR

_NUM = (int, float)


def robot_path(out: str | os.PathLike[str], k: int) -> str:
    """Where robot k's record is in run directory `out`."""
    return os.path.join(out, ROBOTS_DIR, f"r{k}.json")


def _number(v: Any) -> bool:
    return v is None or (isinstance(v, _NUM) and not isinstance(v, bool))


@dataclass(frozen=True)
class RobotStats:
    """One robot's record (see the module's docstring); `data` is the whole file."""

    data: Mapping[str, Any]

    @property
    def cpu_s(self) -> float | None:
        return self.data.get("cpu_s")

    @property
    def max_rss_mb(self) -> float | None:
        return self.data.get("max_rss_mb")

    @property
    def latency_ms(self) -> Mapping[str, Any]:
        """Latencies by kind ({"answer": {"p50": ...}, ...}); empty when none were kept."""
        return self.data.get("latency_ms") or {}

    @property
    def thread_cpu_s(self) -> Mapping[str, float]:
        """CPU seconds per thread of the robot; empty when none were kept."""
        return self.data.get("thread_cpu_s") or {}

    def to_dict(self) -> dict[str, Any]:
        return dict(self.data)

    @classmethod
    def from_dict(cls, d: Any) -> RobotStats:
        """ValueError naming the key unless `d` is a record its readers can use."""
        if not isinstance(d, dict):
            raise ValueError("not a JSON object")
        for key in ("cpu_s", "max_rss_mb"):
            if not _number(d.get(key)):
                raise ValueError(f"{key} is not a number")
        for key in ("latency_ms", "thread_cpu_s"):
            if d.get(key) is not None and not isinstance(d[key], dict):
                raise ValueError(f"{key} is not an object")
        if not all(_number(v) and v is not None for v in (d.get("thread_cpu_s") or {}).values()):
            raise ValueError("thread_cpu_s holds a value that is not a number")
        return cls(MappingProxyType(dict(d)))


def write(out: str | os.PathLike[str], k: int, record: Mapping[str, Any]) -> None:
    """Robot k's record, written atomically."""
    write_json_atomic(robot_path(out, k), dict(record))


def read(out: str | os.PathLike[str], k: int) -> RobotStats | None:
    """Robot k's record; None when it has none that can be read (see the module's docstring)."""
    try:
        data = boundedfile.read(robot_path(out, k), boundedfile.MAX_JSON_BYTES)
        return RobotStats.from_dict(json.loads(data))
    except (boundedfile.Refused, ValueError, RecursionError):
        return None
