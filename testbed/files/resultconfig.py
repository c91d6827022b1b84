"""result.json's `config` as one type: `ResultConfig`, the run options result.json repeats
(those the option table, testbed.files.runconfig, marks in_result) with the defaults of the
runs before each option was recorded.

`CONFIG_KEYS` are the keys result.json's config repeats at its top, in the file's order;
every other option of config.json goes under its `extra`. The fields are those keys and
`FROM_EXTRA`, each annotated with its option's kind and read against it. The option table
holds itself to them as it is made (`check_options`: a TypeError at its import), so an
option marked in_result cannot be left out of result.json's config, and this module, which
every reader of result.json loads, needs nothing of the table. The defaults here are the
only place of the old files' defaults (docs/run-results.md): values of the runs before the
option (a unit test holds them equal to today's defaults).
"""

from __future__ import annotations

import dataclasses
import typing
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from testbed.files.resultvalues import EMPTY, NUM, ResultError, get_mapping, get_value, plain
from topology.spec import CELL_M, VETH

# The keys of config.json that result.json repeats under "config", in the file's order (the
# run options marked in_result, in the table's order); the rest go under "extra".
CONFIG_KEYS = ("robots", "comm_range", "laser_range", "seed", "time_scale", "routing", "map",
               "loss_pct", "delay_ms", "capture", "max_steps", "coordination",
               "start")  # fmt: skip
# The run options under "extra" that ResultConfig gives as fields of their own.
FROM_EXTRA = ("medium", "wifi_standard", "wifi_rate")
# What runs before an option was recorded had:
DEFAULT_VARIANT = ("ours", "corner")  # (coordination, start)
DEFAULT_ROUTING = "aodv"
DEFAULT_MEDIUM = VETH
# Written out, not imported (node.messaging.DEFAULT, DEFAULT_MAPS, testbed.files.failures.NONE
# say today's): what a run made before the option was recorded had, whatever today's is.
DEFAULT_MIDDLEWARE = "nanomsg"
DEFAULT_MAPS = "flood"
DEFAULT_BATTERY_FAILURE = "none"
DEFAULT_MAP_SIZE = (400, 400)  # the empty terrain's [rows, cols]


@dataclass(frozen=True)
class ResultConfig:
    """result.json's `config`: what the run was asked to do, defaults applied. The fields are
    run options (testbed.files.runconfig): those result.json repeats (in_result, CONFIG_KEYS)
    and FROM_EXTRA; their kinds are the options', their defaults those of the runs before
    the option was recorded (set here only)."""

    robots: int
    comm_range: float
    laser_range: float
    time_scale: float | None = None
    routing: str = DEFAULT_ROUTING
    map: str | None = None
    loss_pct: float = 0.0
    delay_ms: float = 0.0
    coordination: str = DEFAULT_VARIANT[0]
    start: str = DEFAULT_VARIANT[1]
    seed: int | None = None
    capture: bool = False
    max_steps: int | None = None
    medium: str = DEFAULT_MEDIUM  # from `extra`
    wifi_standard: str | None = None  # ns3-wifi only (None: the run did not say)
    wifi_rate: str | None = None  # ns3-wifi only; "" is the standard's fastest
    extra: Mapping[str, Any] = field(default_factory=lambda: EMPTY)  # the rest of config.json

    @property
    def map_name(self) -> str:
        """The map's file stem, or "empty" for the empty terrain."""
        return "empty" if not self.map else Path(self.map).stem

    def _named(self, key: str, default: str) -> str:  # `default`: runs before the option
        name = self.extra.get(key)
        return name if isinstance(name, str) else default

    @property
    def middleware(self) -> str:
        return self._named("middleware", DEFAULT_MIDDLEWARE)

    @property
    def maps(self) -> str:
        return self._named("maps", DEFAULT_MAPS)

    @property
    def battery_failure(self) -> str:
        return self._named("battery_failure", DEFAULT_BATTERY_FAILURE)

    @property
    def map_cell(self) -> Any:  # unchecked: the reader checks it
        return self.extra.get("map_cell") or CELL_M

    @property
    def map_size(self) -> Any:  # [rows, cols], unchecked
        return self.extra.get("map_size") or list(DEFAULT_MAP_SIZE)

    def to_dict(self) -> dict[str, Any]:
        out = {k: getattr(self, k) for k in CONFIG_KEYS}
        out["extra"] = plain(self.extra)
        return out

    @classmethod
    def from_config(cls, config: Mapping[str, Any]) -> ResultConfig:
        """From config.json's contents (a run's whole configuration): the contract's keys,
        and everything else under `extra`."""
        doc = {k: config[k] for k in CONFIG_KEYS}
        doc["extra"] = {k: v for k, v in config.items() if k not in CONFIG_KEYS}
        return cls.from_dict(doc)

    @classmethod
    def from_dict(cls, c: Mapping[str, Any]) -> ResultConfig:
        """From result.json's `config` (or a sweep plan's, which keeps everything at the
        top); ResultError when malformed. Each field is checked against its option's kind;
        one absent at the top is looked for under `extra` (where result.json keeps the
        options it does not repeat, and older runs kept coordination and start), then takes
        the field's default (that of runs before the option); a field without one is
        required."""
        extra = get_mapping(c, "extra")
        values: dict[str, Any] = {}
        for f in _OPTION_FIELDS:
            kind = _KIND[f.name]
            if kind is bool:  # a flag: whatever the file holds, as true or false
                values[f.name] = bool(c.get(f.name))
                continue
            value = get_value(c, f.name, _KINDS[kind])
            if value is None:
                value = get_value(extra, f.name, _KINDS[kind])
            if value is None and f.default is dataclasses.MISSING:
                raise ResultError(f"no {f.name!r}")
            values[f.name] = f.default if value is None else value
        return cls(**values, extra=extra)


_KINDS: dict[type, tuple[type, ...]] = {int: (int,), float: NUM, str: (str,), bool: (bool,)}
# ResultConfig's fields but `extra`: run options, each checked against its annotation's kind
# (the option's: check_options).
_OPTION_FIELDS = tuple(f for f in dataclasses.fields(ResultConfig) if f.name != "extra")
_HINTS = typing.get_type_hints(ResultConfig)
_KIND: dict[str, type] = {
    f.name: next(a for a in (_HINTS[f.name], *typing.get_args(_HINTS[f.name])) if a in _KINDS)
    for f in _OPTION_FIELDS
}


def check_options(options: Iterable[Any]) -> None:
    """TypeError unless the option table `options` (testbed.files.runconfig.OPTIONS, which
    calls this as it is made) marks in_result exactly CONFIG_KEYS, in order, and
    ResultConfig's fields are those keys and FROM_EXTRA, each annotated with its option's
    kind: an option marked in_result cannot be left out of result.json's config."""
    by_name = {o.name: o for o in options}
    marked = tuple(o.name for o in by_name.values() if o.in_result)
    if marked != CONFIG_KEYS:
        raise TypeError(f"the options marked in_result {marked} are not CONFIG_KEYS")
    names = [f.name for f in _OPTION_FIELDS]
    if sorted(names) != sorted([*CONFIG_KEYS, *FROM_EXTRA]):
        raise TypeError(f"ResultConfig's fields {names} are not {[*CONFIG_KEYS, *FROM_EXTRA]}")
    for name in names:
        kind, hint = by_name[name].kind, _HINTS[name]
        if kind not in (hint, *typing.get_args(hint)):
            raise TypeError(f"ResultConfig.{name} is {hint}, not its option's {kind.__name__}")
