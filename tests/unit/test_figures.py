"""The numbers behind each figure, checked against the runs' own result.json files."""

import csv
import json
import statistics

import numpy as np
import pytest
from matplotlib.container import ErrorbarContainer
from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

from testbed.analysis import figures, pathsfig, plots, tables
from testbed.analysis.rows import MeanRange, Spread
from testbed.analysis.runs import DEFAULT_VARIANT, load_runs
from testbed.analysis.tables import Fig2Row, RoutingMeans, RoutingRow
from testbed.files import routingfile
from testbed.sweep import file as sweepfile
from tests.unit.test_sweep_synthetic import make_sweep, result_doc, timer_plans, write_run


def small_spec(**kw):
    base = dict(robots=(1, 2, 5, 10), comm_range=(5.0, 20.0), laser_range=(2.0, 1.5), runs=2)
    base.update(kw)
    return sweepfile.SweepSpec.of(**base)


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep")
    make_sweep(out, small_spec())
    made = figures.make_all(out, metrics_of=lambda run: None)
    return out, made


def steps_from_result_file(path):
    """Exploration steps recomputed straight from the contract, independently of figures.py."""
    doc = json.loads(path.read_text())
    vals = [
        r["finish_step"] if r["finish_step"] is not None else doc["steps"]
        for r in doc["robots"].values()
    ]
    return sum(vals) / len(vals)


def test_fig2_numbers_match_the_runs(made):
    out, m = made
    rows = json.loads((out / "figures" / "fig2.json").read_text())
    assert len(rows) == 4 * 2 * 2  # teams x ranges x lasers
    for row in rows:
        per_run = [
            steps_from_result_file(out / "runs" / rid / "result.json") for rid in row["runs"]
        ]
        assert len(per_run) == row["n"] == 2
        assert row["mean"] == pytest.approx(statistics.fmean(per_run))
        assert row["min"] == pytest.approx(min(per_run))
        assert row["max"] == pytest.approx(max(per_run))
        for rid in row["runs"]:
            cfg = json.loads((out / "runs" / rid / "result.json").read_text())["config"]
            assert (cfg["robots"], cfg["comm_range"], cfg["laser_range"]) == (
                row["robots"],
                row["comm_range"],
                row["laser_range"],
            )
    # the CSV carries the same numbers
    with (out / "figures" / "fig2.csv").open() as f:
        csv_rows = list(csv.DictReader(f))
    assert [float(r["mean"]) for r in csv_rows] == pytest.approx([r["mean"] for r in rows])


def test_figure_files_exist(made):
    out, m = made
    for name in ("fig2a", "fig2b", "fig4"):
        for ext in ("png", "pdf"):
            p = out / "figures" / f"{name}.{ext}"
            assert p.is_file() and p.stat().st_size > 1000
    assert not (out / "figures" / "routing.png").exists()  # no captures, no routing figure
    assert not (out / "figures" / "impairments.png").exists()


def test_fig4_intervals_match_the_plans(made):
    out, m = made
    rows = json.loads((out / "figures" / "fig4.json").read_text())
    assert sorted({r["robots"] for r in rows}) == [1, 2, 5, 10]
    assert {(r["laser_range"], r["comm_range"]) for r in rows} == {(2.0, 20.0)}
    for rid in {r["run"] for r in rows}:
        assert rid.endswith("-k1")
        doc = json.loads((out / "runs" / rid / "result.json").read_text())
        expected = []
        for name, robot in doc["robots"].items():
            steps = sorted(p["step"] for p in robot["plans"])
            expected += [(name, b, b - a) for a, b in zip(steps, steps[1:], strict=False)]
        got = [(r["robot"], r["step"], r["interval"]) for r in rows if r["run"] == rid]
        assert sorted(got) == sorted(expected)


def test_only_usable_unimpaired_runs_count(tmp_path):
    s = small_spec(robots=(2,), comm_range=(5.0,), laser_range=(2.0,), runs=3)
    runs = sweepfile.expand(s)
    write_run(tmp_path, runs[0])
    crashed = result_doc(runs[1].config, [10, 20], 30, status="robot_crashed")
    write_run(tmp_path, runs[1], crashed)
    # a step-capped run: the unfinished robot counts the final step
    capped = result_doc(runs[2].config, [100, None], 3000, status="step_cap")
    write_run(tmp_path, runs[2], capped)
    rows = tables.fig2_rows(load_runs(tmp_path))
    assert len(rows) == 1
    assert rows[0].runs == (runs[0].run_id, runs[2].run_id)
    assert rows[0].steps_per_run[1] == (100 + 3000) / 2


def test_unreadable_results_are_skipped(tmp_path):
    runs = sweepfile.expand(small_spec(robots=(1,), comm_range=(5.0,), laser_range=(2.0,)))
    write_run(tmp_path, runs[0])
    bad = tmp_path / "runs" / runs[1].run_id
    bad.mkdir(parents=True)
    (bad / "result.json").write_text("{not json")
    assert [r.run_id for r in load_runs(tmp_path)] == [runs[0].run_id]


def test_plan_causes_are_counted(tmp_path):
    run = sweepfile.expand(small_spec(robots=(2,), comm_range=(5.0,), laser_range=(2.0,)))[0]
    plans = {1: timer_plans(100, requests=3), 2: timer_plans(100)}
    write_run(tmp_path, run, result_doc(run.config, [90, 95], 100, plans))
    (row,) = tables.plan_cause_rows(load_runs(tmp_path))
    assert row.start == 2 and row.request == 3 and row.timer == 2 * 4


def test_routing_and_impairment_tables(tmp_path):
    s = small_spec(robots=(5,), comm_range=(10.0,), laser_range=(2.0,), loss_pct=(0.0, 30.0))
    runs = make_sweep(tmp_path, s)
    fake = {
        r.run_id: {
            "overhead_packets": 0.1 * (1 + r.index),
            "pdf": 1.0 - r.config.loss_pct / 100 - 0.01 * r.index,
            "delay_ms_median": 1.0,
            "throughput_bps": 1000.0,
            "control_tx_packets": 10,
            "tx_packets": 100,
            "daemon_comparison": {"daemon_tx_packets": 10, "relative_difference": 0.0},
        }
        for r in runs
    }
    m = figures.make_all(tmp_path, metrics_of=lambda run: routingfile.parse(fake[run.run_id]))
    routing = m.tables.routing
    assert len(routing) == 1  # the unimpaired point only
    assert routing[0].n == 2
    assert routing[0].means.overhead_packets.mean == pytest.approx(0.25)
    imp = m.tables.impairments
    assert [r.loss_pct for r in imp] == [0.0, 30.0]
    assert imp[1].pdf.mean == pytest.approx(0.70 - 0.015)
    steps = {
        r.run_id: steps_from_result_file(tmp_path / "runs" / r.run_id / "result.json") for r in runs
    }
    lossy = [steps[r.run_id] for r in runs if r.config.loss_pct == 30.0]
    assert imp[1].steps.mean == pytest.approx(statistics.fmean(lossy))
    for name in ("routing", "impairments"):
        assert (tmp_path / "figures" / f"{name}.png").is_file()
        assert (tmp_path / "figures" / f"{name}.pdf").is_file()
        assert (tmp_path / "figures" / f"{name}.csv").is_file()


def test_path_pictures_are_collected(tmp_path):
    runs = make_sweep(tmp_path, small_spec(robots=(1, 2), comm_range=(5.0,), laser_range=(2.0,)))
    # a PNG's signature and header (what is copied), then the run's id to tell them apart
    head = b"\x89PNG\r\n\x1a\n" + (13).to_bytes(4, "big") + b"IHDR" + bytes([0, 0, 0, 1] * 2)
    for r in runs:
        (tmp_path / "runs" / r.run_id / "paths.png").write_bytes(head + r.run_id.encode())
    made = figures.make_all(tmp_path, metrics_of=lambda run: None)
    got = sorted(p.name for p in (tmp_path / "figures" / "paths").iterdir())
    assert got == ["n01-c5-l2-k1.png", "n02-c5-l2-k1.png"]  # first run of each point
    assert (tmp_path / "figures" / "paths" / got[0]).read_bytes().endswith(b"n01-c5-l2-k1")
    assert len([f for f in made.files if f.parent.name == "paths"]) == 2


def _fig2_one_run_per_point():
    return [
        Fig2Row(*DEFAULT_VARIANT, 2.0, comm, n, Spread.of([2000.0 / n]), (2000.0 / n,), ())
        for comm in (5.0, 20.0) for n in (1, 2, 3)
    ]  # fmt: skip


def test_fig2_has_whole_team_sizes_and_n_per_point():
    fig = plots.fig2_figure(_fig2_one_run_per_point(), 2.0, "a")
    ax = fig.axes[0]
    ticks = [t for t in ax.get_xticks() if ax.get_xlim()[0] <= t <= ax.get_xlim()[1]]
    assert ticks and all(float(t).is_integer() for t in ticks)  # no 1.25, 1.5 robots
    texts = [t.get_text() for t in ax.texts]
    assert texts.count("n=1") == 6
    assert any("no interval" in t for t in texts)
    plots.plt.close(fig)


def test_no_legend_entry_for_error_bars_that_are_not_drawn():
    fig = plots.fig2_figure(_fig2_one_run_per_point(), 2.0, "a")
    handles, labels = fig.axes[0].get_legend_handles_labels()
    assert labels == ["range 5 m", "range 20 m"]
    assert not any(isinstance(h, ErrorbarContainer) for h in handles)
    assert not fig.axes[0].containers  # nothing to draw: no bars at all
    plots.plt.close(fig)
    # with intervals, the bars are drawn, and still no legend entry of their own
    rows = [
        Fig2Row(*DEFAULT_VARIANT, 2.0, r.comm_range, r.robots,
                Spread(3, r.steps.mean, r.steps.mean, r.steps.mean, 1.0, r.steps.mean - 50,
                       r.steps.mean + 50), (), ())
        for r in _fig2_one_run_per_point()
    ]  # fmt: skip
    fig = plots.fig2_figure(rows, 2.0, "a")
    handles, labels = fig.axes[0].get_legend_handles_labels()
    assert labels == ["range 5 m", "range 20 m"] and len(fig.axes[0].containers) == 2
    plots.plt.close(fig)


def test_routing_panels_have_whole_team_sizes():
    means = RoutingMeans(**{k: MeanRange(0.5, 0.5, 0.5) for k in tables.ROUTING_FIELDS})
    rows = [RoutingRow(5.0, n, 1, means, (), True) for n in (1, 2, 3)]
    fig = plots.routing_figure(rows)
    for ax in fig.axes:
        ticks = [t for t in ax.get_xticks() if ax.get_xlim()[0] <= t <= ax.get_xlim()[1]]
        assert all(float(t).is_integer() for t in ticks)
        assert not ax.containers  # min == max: no bar, no legend entry for one
    plots.plt.close(fig)


def test_path_pictures_have_start_markers_a_scale_bar_and_names_inside_the_frame(tmp_path):
    run = sweepfile.expand(small_spec(robots=(2,), comm_range=(5.0,), laser_range=(2.0,)))[0]
    d = write_run(tmp_path, run)
    # robot 1 ends in the map's bottom-right corner, robot 2 at its top-left edge
    rows = ["step,x1,y1,x2,y2"] + [f"{s},{1 + s},{1 + s},{5 - s * 0.2},{3 - s * 0.15}"
                                   for s in range(20)]  # fmt: skip
    (d / "positions.csv").write_text("\n".join(rows) + "\n")
    (d / "display").mkdir()
    np.save(d / "display" / "map.npy", np.ones((400, 400), dtype=np.uint8))  # 20 m x 20 m
    rec = load_runs(tmp_path)[0]
    paths = pathsfig.read_positions(d)
    assert paths[1][0] == (1.0, 1.0) and paths[2][-1] == pytest.approx((1.2, 0.15))
    fig = pathsfig.paths_figure(rec, paths)
    ax = fig.axes[0]
    starts = [ln for ln in ax.lines if ln.get_marker() == "s" and len(ln.get_xdata()) == 1]
    assert [(ln.get_xdata()[0], ln.get_ydata()[0]) for ln in starts] == [(1.0, 1.0), (5.0, 3.0)]
    assert any(isinstance(a, AnchoredSizeBar) for a in ax.artists)
    fig.canvas.draw()
    frame = ax.get_window_extent()
    names = [t for t in ax.texts if t.get_text() in ("r1", "r2")]
    assert len(names) == 2
    for t in names:  # each name drawn wholly inside the axes, even at the map's edge
        box = t.get_window_extent()
        assert frame.x0 <= box.x0 and box.x1 <= frame.x1
        assert frame.y0 <= box.y0 and box.y1 <= frame.y1
    pathsfig.plt.close(fig)
    figures.collect_paths([rec], tmp_path / "out")
    assert (tmp_path / "out" / f"{run.run_id}.png").read_bytes()[:4] == b"\x89PNG"


def test_every_study_has_its_sweep_its_tables_and_its_section():
    """figures.STUDIES, the one list of the comparisons: each names a shipped sweep file,
    has the two Tables fields it fills, and the report renders its section from them."""
    import dataclasses
    import inspect
    from pathlib import Path

    from testbed.analysis import figures, report

    fields = {f.name for f in dataclasses.fields(figures.Tables)}
    experiments = Path(figures.__file__).resolve().parents[1] / "experiments"
    for s in figures.STUDIES:
        assert (experiments / s.sweep).is_file(), s.sweep
        assert {s.name, f"{s.name}_runs"} <= fields
        assert s.section([]) == []  # nothing compared, no section
        assert s.tables([], {}) == ([], [])
    assert "figures.STUDIES" in inspect.getsource(report)
    assert len({s.name for s in figures.STUDIES}) == len(figures.STUDIES)
