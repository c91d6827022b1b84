"""A run's config.json as one type: `RunConfigFile`, which testbed.run.prepare writes first
of all a run's files and the run's results and the view's replay read.

The document is the run's options (testbed.files.runconfig.RunConfig.to_dict, the table's keys)
and what preparing the run found (`map_size` [rows, cols], `starts`, `timer_phases`, the
display robot and its `display_pos`, the testbed's `name`, the `snapshots`, a planned
`battery_kill`), keys in the order written; `to_dict()` is the file. `result_config()` is
the part result.json repeats (testbed.files.resultconfig.ResultConfig, the file's one description
of the run's options and of their old runs' defaults).

A config.json may come from elsewhere (the view replays any run directory): `view()` checks
the fields the view draws (`robots` a whole number 1..MAX_ROBOTS, `comm_range` 0..
MAX_COORD_M, `map_cell`, `map_size` [rows, cols] of whole cells, `display_pos` [x, y]),
each a ConfigError naming the key; and `read` takes the file through the one bounded reader
(common.boundedfile), refusing what is not a regular file holding a JSON object. Runs
before the file said so: CELL_M cells, a 20 m x 20 m map, no display position.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

from common import boundedfile
from common.jsonfile import write_json_atomic
from testbed.files.resultfile import ResultConfig
from topology.names import MAX_ROBOTS
from topology.spec import CELL_M, MAX_COORD_M

CONFIG_NAME = "config.json"
MAX_MAP_CELLS = 1 << 20  # cells along one side of the map (a run's maps have hundreds)
OLD_MAP_M = (20.0, 20.0)  # the map of runs whose config.json did not give its size


class ConfigError(ValueError):
    """A config.json that cannot be read as one; str() is one line naming the key."""


def config_path(out: str | os.PathLike[str]) -> str:
    """Where a run directory's config.json is."""
    return os.path.join(out, CONFIG_NAME)


@dataclass(frozen=True)
class ViewConfig:
    """What the view draws from a config.json, checked."""

    robots: int
    comm_range: float
    map_m: list[float]  # [width, height]
    map_cell: float
    display: list[float]  # [x, y], or [] without a display position
    map: Any  # what it names, unchecked: testbed.view.served decides whether to serve it


def _number(value: Any, key: str, lo: float, hi: float) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(f"{key} is not a number")
    if not (math.isfinite(value) and lo <= value <= hi):
        raise ConfigError(f"{key} {value:g} is not in {lo:g}..{hi:g}")
    return value


@dataclass(frozen=True)
class RunConfigFile:
    """The whole config.json (see the module's docstring)."""

    data: Mapping[str, Any]

    def to_dict(self) -> dict[str, Any]:
        return dict(self.data)

    def result_config(self) -> ResultConfig:
        """result.json's `config` (the contract's keys, the rest under `extra`)."""
        return ResultConfig.from_config(self.data)

    def view(self) -> ViewConfig:
        """The fields the view draws, checked; ConfigError naming the key otherwise."""
        c = self.data
        robots = _number(c.get("robots"), "robots", 1, MAX_ROBOTS)
        if robots != int(robots):
            raise ConfigError(f"robots {robots:g} is not a whole number")
        comm_range = float(_number(c.get("comm_range"), "comm_range", 0, MAX_COORD_M))
        cell = float(_number(c.get("map_cell", CELL_M), "map_cell", 1e-6, 1e3))
        size = c.get("map_size")
        if size is None:
            map_m = list(OLD_MAP_M)
        else:
            if not (isinstance(size, list) and len(size) == 2):
                raise ConfigError("map_size is not [rows, cols]")
            rows, cols = (_number(v, "map_size", 1, MAX_MAP_CELLS) for v in size)
            map_m = [int(cols) * CELL_M, int(rows) * CELL_M]
        display = c.get("display_pos") or []
        if display:
            if not (isinstance(display, list) and len(display) == 2):
                raise ConfigError("display_pos is not [x, y]")
            display = [float(_number(v, "display_pos", -MAX_COORD_M, MAX_COORD_M))
                       for v in display]  # fmt: skip
        return ViewConfig(int(robots), comm_range, map_m, cell, display, c.get("map"))

    @classmethod
    def from_dict(cls, doc: Any) -> RunConfigFile:
        if not isinstance(doc, dict):
            raise ConfigError("not a JSON object")
        return cls(MappingProxyType(dict(doc)))


def write(out: str | os.PathLike[str], config: Mapping[str, Any]) -> RunConfigFile:
    """The run directory's config.json, written atomically; what it holds."""
    written = RunConfigFile.from_dict(dict(config))
    write_json_atomic(config_path(out), written.to_dict())
    return written


def read(path: str | os.PathLike[str]) -> RunConfigFile:
    """The config.json at `path`; boundedfile.Refused when it is not a regular file of
    bounded size, ConfigError when it is not a JSON object."""
    try:
        doc = json.loads(boundedfile.read(path, boundedfile.MAX_JSON_BYTES))
    except (ValueError, RecursionError):
        doc = None
    return RunConfigFile.from_dict(doc)
