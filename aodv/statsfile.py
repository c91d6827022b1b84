"""An AODV daemon's statistics file as one type: `DaemonStats`, which the daemon writes
(aodv.stats.Stats.snapshot, every STATS_PERIOD and as it stops) and the run's results (the
fidelity verdict's timer lateness), the analysis (packets and bytes sent, discoveries), the
live view and the benchmarks read.

The daemon writes it as `rK.aodv.json` in the testbed's state directory
(topology.routing.aodv_stats_file); a run keeps a copy as `aodv/rK.json` in its directory
(`run_stats_path`, `run_stats_files`). `to_json()` is the file (written with sorted keys,
so the fields' order is not the file's); `read(path)` takes it through the one bounded
reader (common.boundedfile) and checks what the readers use:

- an object holding `messages_sent`, which every version of the daemon wrote;
- the counts (`bytes_sent`, `route_installs`, `discoveries_ok`, the per-kind maps such as
  `messages_sent` and `dropped`, ...) whole numbers 0..MAX_COUNT; `robot` and `addr`
  strings, `pid` a whole number, `uptime_s` and `cpu_s` numbers;
- `routes` an object of objects; `discoveries` a list of objects whose `ok` is true or
  false, `dest` a string, `latency_s`, `round_latency_s` and `t` numbers, and a successful
  one has its `latency_s`;
- `timer_lateness_ms` an object of objects, each with whole numbers `n` and `late`, a
  number `max`, an object `hist` and a list `worst` of [due, fired, ms late] numbers.

A file that fails is a `StatsError`, one line naming the file and the key. Keys that files
of older daemons lack get their defaults here and only here: nothing not transmitted, no
protocol drops or local repairs, no timer lateness (None), no pid, uptime or CPU time.
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

from common import boundedfile
from common.jsonfile import write_atomic, write_json_atomic

RUN_DIR = "aodv"  # a run directory's folder of the daemons' statistics
MAX_COUNT = 10**15  # more packets or bytes than any run sends
_EMPTY: Mapping[str, Any] = MappingProxyType({})


class StatsError(ValueError):
    """A statistics file that cannot be read as one; str() is one line naming the key (and
    the file, when it was read from one)."""


def run_stats_path(run_dir: str | os.PathLike[str], k: int) -> Path:
    """Where a run directory keeps robot k's daemon statistics."""
    return Path(run_dir) / RUN_DIR / f"r{k}.json"


def run_stats_files(run_dir: str | os.PathLike[str]) -> list[Path] | None:
    """The daemon statistics a run directory keeps (rK.json, sorted by name); None when it
    has no folder of them (a run without AODV)."""
    folder = Path(run_dir) / RUN_DIR
    return sorted(folder.glob("r*.json")) if folder.is_dir() else None


# ---------------------------------------------------------------- checked values


def _shown(value: Any) -> str:
    """A value as an error message shows it: its repr, at most 40 characters."""
    text = repr(value)
    return text if len(text) <= 40 else text[:39] + "…"


def _label(key: str) -> str:
    """A key of the file as part of an error message's one line."""
    return "".join(c if c.isprintable() else "?" for c in key[:40])


def _number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _count(key: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= MAX_COUNT:
        raise StatsError(f"{key} is {_shown(value)}, not a count (a whole number 0..1e15)")
    return value


def _counts(key: str, value: Any) -> Mapping[str, int]:
    """A map of kinds to counts (messages by type, drops by reason, ...)."""
    if not isinstance(value, dict):
        raise StatsError(f"{key} is {type(value).__name__}, not an object")
    return MappingProxyType({k: _count(f"{key}.{_label(k)}", v) for k, v in value.items()})


def _of(key: str, value: Any, kinds: tuple[type, ...], what: str) -> Any:
    if value is not None and (not isinstance(value, kinds) or isinstance(value, bool)):
        raise StatsError(f"{key} is {_shown(value)}, not {what}")
    return value


def _frozen(value: Any) -> Any:
    """A JSON value with its objects read-only (lists stay lists, as JSON gave them)."""
    if isinstance(value, dict):
        return MappingProxyType({k: _frozen(v) for k, v in value.items()})
    if isinstance(value, list):
        return [_frozen(v) for v in value]
    return value


def _plain(value: Any) -> Any:
    """A value as JSON holds it: mappings as dicts, tuples as lists."""
    if isinstance(value, Mapping):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


def _json_value(value: Any) -> Any:
    """json.dumps' `default`: a read-only mapping as a dict (tuples are lists already)."""
    if isinstance(value, Mapping):
        return dict(value)
    raise TypeError(f"{type(value).__name__} is not JSON")


def _objects(key: str, value: Any) -> dict[str, dict[str, Any]]:
    """`value`, an object of objects; StatsError naming `key` otherwise."""
    if not isinstance(value, dict) or not all(isinstance(v, dict) for v in value.values()):
        raise StatsError(f"{key} is not an object of objects")
    return value


def _discovery(i: int, d: Any) -> Mapping[str, Any]:
    where = f"discoveries[{i}]"
    if not isinstance(d, dict):
        raise StatsError(f"{where} is not an object")
    if not isinstance(d.get("ok"), bool):
        raise StatsError(f"{where}.ok is {_shown(d.get('ok'))}, not true or false")
    _of(f"{where}.dest", d.get("dest"), (str,), "a string")
    for key in ("latency_s", "round_latency_s", "t"):
        _of(f"{where}.{key}", d.get(key), (int, float), "a number")
    if d["ok"] and d.get("latency_s") is None:
        raise StatsError(f"{where} succeeded without a latency_s")
    return MappingProxyType(dict(d))


def _timer(kind: str, t: dict[str, Any]) -> None:
    where = f"timer_lateness_ms.{_label(kind)}"
    for key in ("n", "late"):
        if key in t:
            _count(f"{where}.{key}", t[key])
    _of(f"{where}.max", t.get("max"), (int, float), "a number")
    _of(f"{where}.hist", t.get("hist"), (dict,), "an object")
    worst = t.get("worst")
    if worst is not None and not (
        isinstance(worst, list)
        and all(isinstance(w, list) and len(w) == 3 and all(map(_number, w)) for w in worst)
    ):
        raise StatsError(f"{where}.worst is not a list of [due, fired, ms late]")


# ---------------------------------------------------------------- the file


def _no_counts() -> Any:
    """A field's default: an empty map (a key older daemons did not write)."""
    return field(default_factory=lambda: _EMPTY)


_COUNTS = ("bytes_not_transmitted", "bytes_sent", "bytes_received", "route_installs",
           "route_deletes", "packets_buffered", "packets_released", "icmp_unreachable_sent",
           "route_use_refreshes", "discoveries_ok", "discoveries_failed")  # fmt: skip
_COUNT_MAPS = ("messages_sent", "messages_not_transmitted", "messages_received", "dropped",
               "protocol_dropped", "local_repairs")  # fmt: skip


@dataclass(frozen=True, kw_only=True)
class DaemonStats:
    """One daemon's statistics file (see the module's docstring); the fields are its keys."""

    robot: str | None = None  # "rK"
    addr: str | None = None
    pid: int | None = None
    uptime_s: float | None = None
    messages_sent: Mapping[str, int]  # by message type (RREQ, RREP, RERR, HELLO, ...)
    messages_not_transmitted: Mapping[str, int] = _no_counts()  # handed over, reported unsent
    bytes_not_transmitted: int = 0
    messages_received: Mapping[str, int] = _no_counts()
    bytes_sent: int = 0
    bytes_received: int = 0
    dropped: Mapping[str, int] = _no_counts()  # by reason
    protocol_dropped: Mapping[str, int] = _no_counts()  # what the core bounded or refused
    local_repairs: Mapping[str, int] = _no_counts()
    routes: Mapping[str, Mapping[str, Any]] = _no_counts()  # dest -> {next_hop, hops}
    route_installs: int = 0
    route_deletes: int = 0
    packets_buffered: int = 0
    packets_released: int = 0
    icmp_unreachable_sent: int = 0
    route_use_refreshes: int = 0
    discoveries_ok: int = 0
    discoveries_failed: int = 0
    discoveries: tuple[Mapping[str, Any], ...] = ()  # the last 1000: dest, ok, latencies, t
    timer_lateness_ms: Mapping[str, Mapping[str, Any]] | None = None  # hello, expiry
    cpu_s: float | None = None

    @property
    def sent_total(self) -> int:
        """Routing messages sent, of every type."""
        return sum(self.messages_sent.values())

    @property
    def discovery_latencies_s(self) -> list[float]:
        """The latencies of the successful route discoveries kept, oldest first."""
        return [d["latency_s"] for d in self.discoveries if d["ok"]]

    def to_json(self) -> dict[str, Any]:
        return {f.name: _plain(getattr(self, f.name)) for f in dataclasses.fields(self)}

    def write(self, path: str | os.PathLike[str], *, compact: bool = False) -> None:
        """The file at `path`, atomically (a temporary file renamed), keys sorted.
        `compact`: on one line, by json's compiled encoder, for the daemon's rewrites every
        STATS_PERIOD: indented, the file goes through json's Python encoder, and with the
        routes and discoveries of a 75-robot team those rewrites took more of a daemon's
        CPU than its packets did."""
        if not compact:
            write_json_atomic(path, self.to_json(), sort_keys=True)
            return
        write_atomic(path, self.compact_text())

    def compact_text(self) -> str:
        """The file's contents on one line (keys sorted), as `write(compact=True)` writes it."""
        doc = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        return json.dumps(doc, sort_keys=True, separators=(",", ":"), default=_json_value) + "\n"

    @classmethod
    def from_json(cls, doc: Any) -> DaemonStats:
        """From the file's contents; StatsError naming the key when malformed."""
        if not isinstance(doc, dict):
            raise StatsError("not a JSON object")
        if "messages_sent" not in doc:
            raise StatsError("no 'messages_sent'")
        lateness = doc.get("timer_lateness_ms")
        if lateness is not None:
            for kind, timer in _objects("timer_lateness_ms", lateness).items():
                _timer(kind, timer)
            lateness = _frozen(lateness)
        discoveries = doc.get("discoveries", [])
        if not isinstance(discoveries, list):
            raise StatsError("discoveries is not a list")
        number = (int, float)
        counts: dict[str, Any] = {k: _counts(k, doc[k]) for k in _COUNT_MAPS if k in doc}
        counts.update({k: _count(k, doc[k]) for k in _COUNTS if k in doc})
        return cls(
            robot=_of("robot", doc.get("robot"), (str,), "a string"),
            addr=_of("addr", doc.get("addr"), (str,), "a string"),
            pid=_of("pid", doc.get("pid"), (int,), "a whole number"),
            uptime_s=_of("uptime_s", doc.get("uptime_s"), number, "a number"),
            cpu_s=_of("cpu_s", doc.get("cpu_s"), number, "a number"),
            routes=_frozen(_objects("routes", doc.get("routes", {}))),
            discoveries=tuple(_discovery(i, d) for i, d in enumerate(discoveries)),
            timer_lateness_ms=lateness,
            **counts,
        )

    @classmethod
    def read(cls, path: str | os.PathLike[str]) -> DaemonStats:
        """The file at `path`; StatsError (one line naming the file and the key) when it is
        missing, not a regular file, not JSON or malformed."""
        try:
            return cls.from_json(boundedfile.load_json(path))
        except boundedfile.Refused as r:
            raise StatsError(f"{path}: {boundedfile.describe(r)}") from None
        except StatsError as e:
            raise StatsError(f"{path}: {e}") from None
