"""Every table of testbed.analysis is a list of typed rows (issue 41: every file the testbed
writes and reads again has one type): each kind of row a frozen dataclass, written in its
declared columns by testbed.analysis.rows.columns. Checked here on the source of the modules
that make, write or read the tables: none builds a row as a dict (a dict display, dict(...)
with column names, dict(zip(...)) or a column stored by its name), and every row type is
frozen and written in its fields' order."""

import ast
import dataclasses
import importlib
import json
from pathlib import Path

import pytest

from testbed.analysis import tables
from testbed.analysis.rows import MeanCI, MeanRange, Spread, columns

REPO = Path(__file__).resolve().parents[2]
ROW_MODULES = ("ablation", "figures", "media", "middlewares", "plots", "protocols", "report",
               "rows", "scalecompare", "tables", "verdicts")  # fmt: skip


def _row_types() -> list[type]:
    out = []
    for name in ROW_MODULES:
        mod = importlib.import_module(f"testbed.analysis.{name}")
        out += [v for v in vars(mod).values()
                if isinstance(v, type) and dataclasses.is_dataclass(v)
                and v.__module__ == mod.__name__]  # fmt: skip
    return out


def _column_names() -> set[str]:
    names = set()
    for t in _row_types():
        names |= {f.name for f in dataclasses.fields(t)}
    for prefix in ("steps", "pdf", "overhead_packets", "delay_ms_median", "throughput_bps"):
        names |= {f"{prefix}_{s}" for s in ("mean", "min", "max", "ci_low", "ci_high")}
    return names


COLUMNS = _column_names()


def dict_rows(source: str, columns_: set[str] = COLUMNS) -> list[str]:
    """Where `source` builds a table row as a dict (a dict display of constants is a lookup
    table, not a row)."""
    found = []
    for n in ast.walk(ast.parse(source)):
        if isinstance(n, ast.Dict):
            keys = [k.value for k in n.keys if isinstance(k, ast.Constant)]
            constant = all(isinstance(v, ast.Constant) for v in n.values)  # a lookup table
            if not constant and sum(k in columns_ for k in keys if isinstance(k, str)) >= 2:
                found.append(f"{n.lineno}: a dict display with column names")
        elif isinstance(n, ast.Call) and isinstance(n.func, ast.Name) and n.func.id == "dict":
            if sum(k.arg in columns_ for k in n.keywords) >= 2:
                found.append(f"{n.lineno}: dict(...) with column names")
            first = n.args[0] if n.args else None
            if (isinstance(first, ast.Call) and isinstance(first.func, ast.Name)
                    and first.func.id == "zip" and first.args
                    and isinstance(first.args[0], ast.Tuple | ast.List)):  # fmt: skip
                found.append(f"{n.lineno}: dict(zip(column names, ...))")
        elif (isinstance(n, ast.Subscript) and isinstance(n.ctx, ast.Store)
              and isinstance(n.slice, ast.Constant) and n.slice.value in columns_):  # fmt: skip
            found.append(f"{n.lineno}: a column stored by its name")
    return found


def test_the_check_sees_what_it_must():
    assert dict_rows('row = {"robots": n, "comm_range": c}\n')
    assert dict_rows("row = dict(robots=n, steps=s)\n")
    assert dict_rows('row = dict(zip(("robots", "comm_range"), key))\n')
    assert not dict_rows("by_id = dict(zip(ids, pool.map(f, runs)))\n")
    assert dict_rows('row["n"] = len(items)\n')
    assert not dict_rows('colors = {"timer": "tab:blue", "request": "tab:red"}\n')
    assert not dict_rows("m = metrics.get('pdf') or {}\n")
    assert {"robots", "comm_range", "n", "steps_ci_low", "pdf_mean"} <= COLUMNS


@pytest.mark.parametrize("name", ROW_MODULES)
def test_no_table_row_is_a_dict(name):
    assert dict_rows((REPO / "testbed" / "analysis" / f"{name}.py").read_text()) == []


@pytest.mark.parametrize("t", _row_types(), ids=lambda t: t.__qualname__)
def test_every_row_type_is_frozen(t):
    # figures' holders of the tables, filled in turn; a verdict, its evidence added in turn
    if t.__name__ in ("Tables", "Made", "Verdict"):
        return
    assert t.__dataclass_params__.frozen, t


def test_columns_follow_the_declared_fields():
    row = tables.ImpairmentRow(2, 5.0, 0.0, 1.0, 3, MeanRange(1.0, 0.5, 2.0), MeanRange())
    assert list(columns(row)) == [
        "robots", "comm_range", "delay_ms", "loss_pct", "n", "steps_mean", "steps_min",
        "steps_max", "pdf_mean", "pdf_min", "pdf_max",
    ]  # fmt: skip
    fig2 = tables.Fig2Row("ours", "corner", 2.0, 5.0, 3, Spread.of([1.0, 2.0]), (1.0, 2.0),
                          ("a", "b"))  # fmt: skip
    assert list(columns(fig2)) == [
        "coordination", "start_placement", "laser_range", "comm_range", "robots", "n", "mean",
        "min", "max", "std", "ci_low", "ci_high", "steps_per_run", "runs",
    ]  # fmt: skip
    assert columns(MeanCI(1.0, 0.5, 1.5), "pdf") == {"pdf": 1.0, "pdf_ci_low": 0.5,
                                                      "pdf_ci_high": 1.5}  # fmt: skip


def test_a_table_is_written_in_its_columns(tmp_path):
    causes = tables.PlanCauseRow("r1", "ours", "corner", 2, 5.0, 2.0, 2, 8, 3, {"other": 1})
    tables.write_table([causes], tmp_path / "plans")
    head = (tmp_path / "plans.csv").read_text().splitlines()[0]
    assert head == ("run,coordination,start_placement,robots,comm_range,laser_range,start,"
                    "timer,request,other")  # fmt: skip
    assert json.loads((tmp_path / "plans.json").read_text()) == [columns(causes)]


def test_the_measure_records_hold_the_measures_they_are_named_by():
    """The records of measures generic code reaches by name hold those names, in order."""
    from testbed.analysis import media, middlewares, protocols, scalecompare

    assert tuple(k for k, _, _ in media.COMPARED) == media.COMPARED_KEYS
    assert tuple(k for k, _, _ in middlewares.MEANS) == middlewares.MEANS_KEYS
    assert tables.ROUTING_FIELDS[:-1] == tuple(k for k, _ in tables.ROUTING_METRICS)
    point = protocols.ProtocolPoint(
        "empty",
        "veth",
        5.0,
        2,
        "aodv",
        1,
        None,
        protocols.ProtocolMeasures(*range(len(protocols.METRICS))),
    )
    assert [columns(point)[k] for k in protocols.METRICS] == list(range(len(protocols.METRICS)))
    assert [point.measure(k) for k in protocols.METRICS] == list(range(len(protocols.METRICS)))
    assert {k for k, _, _ in protocols.BESIDE_THE_RULE} <= set(protocols.METRICS)
    runs = {f.name for f in dataclasses.fields(scalecompare.ScaleRun)}
    assert set(scalecompare.MEASURE_KEYS) <= runs


def test_a_row_gives_a_measure_by_name_and_refuses_any_other():
    """`named` and `Measures.of`, the one accessor the rows' of()/measure() share: a measure
    by its table's name, KeyError for a name that is no measure (a field such as `n`, a
    method's name)."""
    from testbed.analysis.media import MediaCompared
    from testbed.analysis.rows import named

    mc = MeanCI(2.0, 1.0, 3.0)
    assert named(mc, "mean", ("mean", "ci_low")) == 2.0
    for wrong in ("ci_high", "nope"):
        with pytest.raises(KeyError):
            named(mc, wrong, ("mean", "ci_low"))
    compared = MediaCompared(*(MeanCI(float(i)) for i in range(6)))
    assert compared.of("pdf") == MeanCI(1.0)
    for wrong in ("of", "nope", "__class__"):
        with pytest.raises(KeyError):
            compared.of(wrong)
