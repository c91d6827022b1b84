"""The numbers behind each figure, checked against the runs' own result.json files."""

import csv
import json
import statistics

import pytest

from testbed import sweepfile
from testbed.analysis import figures
from tests.unit.test_sweep_synthetic import make_sweep, result_doc, timer_plans, write_run


def small_spec(**kw):
    base = dict(robots=(1, 2, 5, 10), comm_range=(5.0, 20.0), laser_range=(2.0, 1.5), runs=2)
    base.update(kw)
    return sweepfile.SweepSpec(**base)


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
    rows = figures.fig2_rows(figures.load_runs(tmp_path))
    assert len(rows) == 1
    assert rows[0]["runs"] == [runs[0].run_id, runs[2].run_id]
    assert rows[0]["steps_per_run"][1] == (100 + 3000) / 2


def test_unreadable_results_are_skipped(tmp_path):
    runs = sweepfile.expand(small_spec(robots=(1,), comm_range=(5.0,), laser_range=(2.0,)))
    write_run(tmp_path, runs[0])
    bad = tmp_path / "runs" / runs[1].run_id
    bad.mkdir(parents=True)
    (bad / "result.json").write_text("{not json")
    assert [r.run_id for r in figures.load_runs(tmp_path)] == [runs[0].run_id]


def test_plan_causes_are_counted(tmp_path):
    run = sweepfile.expand(small_spec(robots=(2,), comm_range=(5.0,), laser_range=(2.0,)))[0]
    plans = {1: timer_plans(100, requests=3), 2: timer_plans(100)}
    write_run(tmp_path, run, result_doc(run.config, [90, 95], 100, plans))
    (row,) = figures.plan_cause_rows(figures.load_runs(tmp_path))
    assert row["start"] == 2 and row["request"] == 3 and row["timer"] == 2 * 4


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
    m = figures.make_all(tmp_path, metrics_of=lambda run: fake[run.run_id])
    routing = m["tables"]["routing"]
    assert len(routing) == 1  # the unimpaired point only
    assert routing[0]["n"] == 2
    assert routing[0]["overhead_packets_mean"] == pytest.approx(0.25)
    imp = m["tables"]["impairments"]
    assert [r["loss_pct"] for r in imp] == [0.0, 30.0]
    assert imp[1]["pdf_mean"] == pytest.approx(0.70 - 0.015)
    steps = {
        r.run_id: steps_from_result_file(tmp_path / "runs" / r.run_id / "result.json") for r in runs
    }
    lossy = [steps[r.run_id] for r in runs if r.config.loss_pct == 30.0]
    assert imp[1]["steps_mean"] == pytest.approx(statistics.fmean(lossy))
    for name in ("routing", "impairments"):
        assert (tmp_path / "figures" / f"{name}.png").is_file()
        assert (tmp_path / "figures" / f"{name}.pdf").is_file()
        assert (tmp_path / "figures" / f"{name}.csv").is_file()


def test_path_pictures_are_collected(tmp_path):
    runs = make_sweep(tmp_path, small_spec(robots=(1, 2), comm_range=(5.0,), laser_range=(2.0,)))
    for r in runs:
        (tmp_path / "runs" / r.run_id / "paths.png").write_bytes(b"\x89PNG " + r.run_id.encode())
    made = figures.make_all(tmp_path, metrics_of=lambda run: None)
    got = sorted(p.name for p in (tmp_path / "figures" / "paths").iterdir())
    assert got == ["n01-c5-l2-k1.png", "n02-c5-l2-k1.png"]  # first run of each point
    assert (tmp_path / "figures" / "paths" / got[0]).read_bytes().endswith(b"n01-c5-l2-k1")
    assert len([f for f in made["files"] if f.parent.name == "paths"]) == 2
