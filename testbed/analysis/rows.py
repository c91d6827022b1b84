"""The records the analysis's tables are made of, and the one way a row becomes the columns
its CSV and JSON files hold.

Theory of operation. Every table of testbed.analysis is a list of frozen dataclass rows,
declared beside the code that makes them (testbed.analysis.tables, .protocols, .media, ...);
the records several tables share are here: `Spread` (a set of runs' n, mean, range, standard
deviation and 95% interval of the mean, as Fig. 2, the ablation and the verdicts read it),
`MeanRange` (mean, min and max over a point's runs, as the routing and impairment figures
draw it) and `MeanCI` (a measure's mean and its 95% interval, as the media and middleware
comparisons judge it); `named` is how a row gives one of its measures by name, and
`Measures` a record of them all.
`columns(row)` names a row's cells in its fields' declared order: a field holding a record
is spelled out as the record's own columns, prefixed with the field's name (`pdf` ->
`pdf_mean`, `pdf_min`, `pdf_max`) unless it is declared `INLINE` (no prefix); a record's
field declared `BARE` is named by the prefix alone (`steps`, `steps_ci_low`,
`steps_ci_high`); a mapping declared inline adds its items as they are (the plan causes a
run had beyond the usual three).
"""

from __future__ import annotations

import dataclasses
import statistics
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from testbed.analysis import stats

# A field's metadata: its record's (or mapping's) columns without the field's name before them.
INLINE: Mapping[str, bool] = {"inline": True}
# A record's field whose column is the record's field name alone (`steps`, beside `steps_ci_low`).
BARE: Mapping[str, bool] = {"bare": True}


@dataclass(frozen=True)
class Spread:
    """n, mean, min, max, std and the 95% interval of the mean of a point's values; std and
    the interval are None (an empty cell) for one value: one run says nothing of the noise."""

    n: int
    mean: float
    min: float
    max: float
    std: float | None
    ci_low: float | None
    ci_high: float | None

    @classmethod
    def of(cls, values: Sequence[float]) -> Spread:
        ci = stats.mean_ci(list(values))
        return cls(
            n=len(values),
            mean=statistics.fmean(values),
            min=min(values),
            max=max(values),
            std=statistics.stdev(values) if len(values) > 1 else None,
            ci_low=ci[1] if ci else None,
            ci_high=ci[2] if ci else None,
        )

    @property
    def ci(self) -> tuple[float, float, float] | None:
        """(mean, low, high) of the 95% interval, None for one value."""
        if self.ci_low is None or self.ci_high is None:
            return None
        return self.mean, self.ci_low, self.ci_high


@dataclass(frozen=True)
class MeanRange:
    """Mean, min and max of a metric over a point's runs; all None when no run had it."""

    mean: float | None = None
    min: float | None = None
    max: float | None = None

    @classmethod
    def of(cls, values: Sequence[float]) -> MeanRange:
        if not values:
            return cls()
        s = Spread.of(values)
        return cls(s.mean, s.min, s.max)


@dataclass(frozen=True)
class MeanCI:
    """A measure's mean over a point's runs (None when no run had it) and the 95% interval
    of that mean (None for fewer than two values); its columns are `KEY`, `KEY_ci_low` and
    `KEY_ci_high`."""

    mean: float | None = field(default=None, metadata=BARE)
    ci_low: float | None = None
    ci_high: float | None = None

    @classmethod
    def of(cls, values: Sequence[float]) -> MeanCI:
        ci = stats.mean_ci(list(values))
        return cls(
            statistics.fmean(values) if values else None,
            ci[1] if ci else None,
            ci[2] if ci else None,
        )

    @property
    def ci(self) -> tuple[float, float, float] | None:
        """(mean, low, high), None without an interval."""
        if self.mean is None or self.ci_low is None or self.ci_high is None:
            return None
        return self.mean, self.ci_low, self.ci_high


class Measures:
    """A frozen record whose fields are a row's measures: `of(key)` gives one by its name
    (KeyError for any other)."""

    def of(self, key: str) -> Any:
        record: Any = self  # a dataclass: every subclass is one
        return named(self, key, [f.name for f in dataclasses.fields(record)])


def named(record: Any, key: str, keys: Sequence[str]) -> Any:
    """The record's field `key`, one of `keys` (a row's measures, as a table names them);
    KeyError for any other name, a field that is no measure included."""
    if key not in keys:
        raise KeyError(key)
    return getattr(record, key)


def columns(row: Any, prefix: str = "") -> dict[str, Any]:
    """The row's cells by column name, in its fields' declared order (see the module's
    docstring for records, inline fields and bare ones)."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(row):
        value = getattr(row, f.name)
        inline = bool(f.metadata.get("inline"))
        name = prefix if prefix and f.metadata.get("bare") else _joined(prefix, f.name)
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            out.update(columns(value, prefix if inline else name))
        elif inline and isinstance(value, Mapping):
            out.update(value)
        else:
            out[name] = value
    return out


def _joined(prefix: str, name: str) -> str:
    return f"{prefix}_{name}" if prefix else name
