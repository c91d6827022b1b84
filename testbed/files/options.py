"""Run options: each declared once, on its `RunConfig` field, and everything else generated.

Theory of operation. A field of `testbed.files.runconfig.RunConfig` that the user may set is
declared with `option(...)`: its kind, bounds, choices, unit and help ride on the dataclass
field (its `metadata`), next to the default. `options()` reads them back as `Option`s, the
one table from which are made:

- `testbed run`'s arguments (`add_to_parser`), with the default and unit in every `--help`
  line, and the `net up` arguments it shares with `run` (`net=True`, same flags and checks);
- a config from parsed arguments (`config_kwargs`: flags whose unit differs from the
  field's, such as `--speed` in m/s for a field in metres per step, are converted here);
- the argv that parses back into a given config (`to_argv`), which a sweep hands each run;
- the keys result.json repeats under `config` (`in_result`: the table is held to
  testbed.files.resultconfig's keys and fields as it is made);
- the checks of a sweep file's `[run]` values and `[grid]` lists (`check_value`), for the
  options marked `sweep`; and for those a sweep may vary, their `GridDim`: where they sit in
  the grid, their part of a run's id and whether they feed its seed (testbed.sweep.file
  expands a grid from these alone).

A unit test holds the loop table -> argparse -> RunConfig -> argv -> argparse closed, as
node/launch.py's `NodeArgs` test does for the robot's command line.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from collections.abc import Callable, Set
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from common.argtypes import number

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

GRID = "grid"  # a sweep file may vary the option in [grid]
RUN = "run"  # a sweep file may fix the option in [run]

# When a grid dimension's part of a run id is shown (GridDim.shown):
ALWAYS = "always"
NONZERO = "nonzero"  # an impairment: only when there is one
CHANGED = "changed"  # only when not the option's default
VARIED = "varied"  # only when the sweep file makes the option a grid dimension


@dataclass(frozen=True)
class GridDim:
    """How an option that a sweep file may vary (`sweep={GRID}`) takes part in a sweep: its
    place in the grid (the nesting of the expansion, and the order of run ids' parts), its
    part of a run's id and when that part is shown, and whether it feeds the run's seed
    (the variants of a point that do not are compared on the same random draws)."""

    order: int
    label: Callable[[Any], str]  # the id part, e.g. 5.0 -> "c5"
    shown: str = ALWAYS
    seeded: bool = False


@dataclass(frozen=True)
class Option:
    """One run option: a `RunConfig` field and how the user sets it."""

    name: str  # the RunConfig field
    kind: type  # int, float, str or bool (a bare flag)
    help: str
    unit: str = ""
    default: Any = None
    required: bool = False
    minimum: float | None = None  # value >= minimum
    above: float | None = None  # value > above
    maximum: float | None = None  # value <= maximum
    choices: tuple[str, ...] | None = None
    metavar: str | None = None
    parse: Callable[[str], Any] | None = None  # argparse type of a structured value
    text: Callable[[Any], str] | None = None  # the inverse of `parse`
    repeat: bool = False  # the flag may be given several times (a tuple of values)
    per_step: float | None = None  # the flag is per second, the field per step of this many s
    default_text: str | None = None  # the default as --help says it, when not the value
    sweep: frozenset[str] = frozenset()  # where a sweep file may set it: GRID, RUN
    # In a sweep's plan only when not the default: options added after the first sweeps, so
    # that the plans (and the run argv) of older sweeps stay as they were.
    newer: bool = False
    net: bool = False  # `testbed net up` takes it too
    # result.json repeats it under `config` (testbed.files.resultconfig.ResultConfig); the other
    # options go under config's `extra`.
    in_result: bool = False
    cli: str | None = None  # the flag, when not --name-with-dashes
    grid: GridDim | None = None  # with sweep={GRID}: how it varies in a sweep

    @property
    def grid_dim(self) -> GridDim:
        """`grid` of an option a sweep may vary (options() holds that each has one)."""
        if self.grid is None:
            raise TypeError(f"option {self.name} is not a grid dimension")
        return self.grid

    @property
    def flag(self) -> str:
        return self.cli or "--" + self.name.replace("_", "-")

    def help_text(self) -> str:
        """The --help line: what it is, its unit and its default (or that it is required)."""
        if self.required:
            tail = "required"
        elif self.default_text is not None:
            tail = f"default {self.default_text}"
        elif self.kind is bool:
            tail = "default off"
        else:
            shown = self.default / self.per_step if self.per_step else self.default
            tail = f"default {shown:g}" if isinstance(shown, float) else f"default {shown}"
        unit = f"{self.unit}; " if self.unit else ""
        bounds = (
            f"; {self.bounds_text()}" if self.kind in (int, float) and self.bounds_text() else ""
        )
        return f"{self.help} ({unit}{tail}{bounds})".replace("%", "%%")

    def bounds_text(self) -> str:
        parts = []
        if self.above is not None:
            parts.append(f"> {self.above:g}")
        if self.minimum is not None:
            parts.append(f">= {self.minimum:g}")
        if self.maximum is not None:
            parts.append(f"<= {self.maximum:g}")
        return " and ".join(parts)


def option(kind: type, help: str, default: Any = dataclasses.MISSING, **kw: Any) -> Any:
    """A RunConfig field that is a run option (see the module docstring); no default: the
    option is required."""
    meta = {"option": {"kind": kind, "help": help, **kw}}
    return dataclasses.field(default=default, metadata=meta)


def options(config_class: type[DataclassInstance]) -> tuple[Option, ...]:
    """The run options of `config_class` (RunConfig), in field order."""
    out = []
    for f in dataclasses.fields(config_class):
        if "option" not in f.metadata:
            continue
        required = f.default is dataclasses.MISSING
        meta = dict(f.metadata["option"])
        meta["sweep"] = frozenset(meta.get("sweep", ()))
        if (GRID in meta["sweep"]) != (meta.get("grid") is not None):
            raise TypeError(f"option {f.name}: sweep={{GRID}} and grid=GridDim(...) go together")
        out.append(Option(name=f.name, default=None if required else f.default,
                          required=required, **meta))  # fmt: skip
    return tuple(out)


# ---------------------------------------------------------------- argparse


def _argtype(opt: Option) -> Callable[[str], Any]:
    if opt.parse is not None:
        return opt.parse
    if opt.kind in (int, float):
        check = number(opt.kind, opt.flag.lstrip("-").replace("-", " "),
                       minimum=opt.minimum, above=opt.above)  # fmt: skip
        maximum = opt.maximum
        if maximum is None:
            return check

        def bounded(text: str) -> int | float:
            value = check(text)
            if value > maximum:
                what = opt.flag.lstrip("-").replace("-", " ")
                raise argparse.ArgumentTypeError(f"{what} must be at most {maximum:g}, not {text}")
            return value

        return bounded
    return str


def add_option(parser: argparse.ArgumentParser, opt: Option, **override: Any) -> None:
    """One option as an argument of `parser` (dest: the field's name)."""
    kw: dict[str, Any] = {"dest": opt.name, "help": opt.help_text()}
    if opt.kind is bool:
        kw["action"] = "store_true"
    else:
        kw["type"] = _argtype(opt)
        if opt.choices is not None:
            kw["choices"] = opt.choices
        if opt.metavar:
            kw["metavar"] = opt.metavar
        if opt.repeat:
            kw["action"], kw["default"] = "append", []
        elif opt.required:
            kw["required"] = True
        else:
            kw["default"] = opt.default / opt.per_step if opt.per_step else opt.default
    kw.update(override)
    parser.add_argument(opt.flag, **kw)


def add_to_parser(parser: argparse.ArgumentParser, opts: tuple[Option, ...]) -> None:
    for opt in opts:
        add_option(parser, opt)


def config_kwargs(args: argparse.Namespace, opts: tuple[Option, ...]) -> dict[str, Any]:
    """The RunConfig keyword arguments of parsed arguments (flag units turned to field units)."""
    kw = {}
    for opt in opts:
        value = getattr(args, opt.name)
        if opt.repeat:
            value = tuple(value)
        elif opt.per_step and value is not None:
            value = value * opt.per_step
        kw[opt.name] = value
    return kw


# ---------------------------------------------------------------- argv


def _word(opt: Option, value: Any) -> str:
    if opt.text is not None:
        return opt.text(value)
    if opt.per_step:
        return f"{value / opt.per_step:.12g}"
    return repr(value) if isinstance(value, float) else str(value)


def to_argv(
    config: DataclassInstance, opts: tuple[Option, ...], always: Set[str] = frozenset()
) -> list[str]:
    """The arguments that parse back into `config`: each option whose value is not its
    default, and those named in `always` (unless None or off)."""
    argv: list[str] = []
    for opt in opts:
        value = getattr(config, opt.name)
        if value is None or value is False:
            continue
        if value == opt.default and opt.name not in always:
            continue
        if value is True:
            argv.append(opt.flag)
        elif opt.repeat:
            for item in value:
                argv += [opt.flag, _word(opt, item)]
        else:
            argv += [opt.flag, _word(opt, value)]
    return argv


# ---------------------------------------------------------------- values from a file


def check_value(opt: Option, value: Any) -> str | None:
    """Why `value` (from TOML) is not a valid value of `opt`, or None. Whole numbers are
    accepted for a float option."""
    if opt.choices is not None:
        if value not in opt.choices:
            return f"expected one of {', '.join(opt.choices)}, got {value!r}"
        return None
    if opt.kind is bool:
        return None if isinstance(value, bool) else f"expected true or false, got {value!r}"
    if opt.kind is str:
        ok = isinstance(value, str) and value
        return None if ok else f"expected a non-empty string, got {value!r}"
    numeric = isinstance(value, int | float) and not isinstance(value, bool)
    if opt.kind is int and not (numeric and isinstance(value, int)):
        return f"expected an integer, got {value!r}"
    if not numeric or not math.isfinite(value):
        return f"expected a number, got {value!r}"
    low_ok = (opt.minimum is None or value >= opt.minimum) and (
        opt.above is None or value > opt.above
    )
    if not low_ok or (opt.maximum is not None and value > opt.maximum):
        return f"value {value!r} out of range (must be {opt.bounds_text()})"
    return None
