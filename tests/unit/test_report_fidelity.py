"""Runs not faithful to their time scale (result.json's `fidelity`, testbed.run.fidelity): the
analysis reads the verdict, leaves such runs out of the figures and verdicts by default,
and the report names and counts them."""

import json

from testbed.analysis import report
from testbed.analysis.runs import load_run, load_runs
from testbed.sweep import file as sweepfile
from tests.unit.test_sweep_synthetic import make_sweep


def mark_unfaithful(
    run_dir, reason="3 of 10 plans applied a step or more late (30.0%, limit 1.0%)"
):
    path = run_dir / "result.json"
    doc = json.loads(path.read_text())
    doc["fidelity"] = {"ok": False, "reason": reason, "measures": {}, "thresholds": {}}
    path.write_text(json.dumps(doc))


def sweep(tmp_path):
    spec = sweepfile.SweepSpec.of(robots=(1, 2), comm_range=(5.0,), laser_range=(2.0,), runs=3)
    runs = make_sweep(tmp_path, spec)
    return [tmp_path / "runs" / r.run_id for r in runs]


def test_the_verdict_is_read_and_an_unfaithful_run_is_not_usable(tmp_path):
    dirs = sweep(tmp_path)
    mark_unfaithful(dirs[0])
    bad, good = load_run(dirs[0]), load_run(dirs[1])
    assert bad.faithful is False and "plans applied" in bad.fidelity_reason
    assert not bad.usable
    assert good.faithful is None and good.usable  # written before verdicts: it counts
    assert all(r.usable for r in load_runs(tmp_path, unfaithful=True))
    assert sum(r.usable for r in load_runs(tmp_path)) == len(dirs) - 1


def test_the_report_names_and_counts_unfaithful_runs_and_leaves_them_out(tmp_path):
    dirs = sweep(tmp_path)
    mark_unfaithful(dirs[0])
    path, _ = report.write_report(tmp_path, metrics_of=lambda run: None)
    text = path.read_text()
    assert "**Not faithful to their time scale: 1 run(s)**, left out of the figures" in text
    assert f"{dirs[0].name} at time scale 1 (3 of 10 plans applied" in text
    fig2 = (tmp_path / "figures" / "fig2.csv").read_text()
    path, _ = report.write_report(tmp_path, metrics_of=lambda run: None, unfaithful=True)
    assert "counted nevertheless (--include-unfaithful)" in path.read_text()
    assert (tmp_path / "figures" / "fig2.csv").read_text() != fig2  # one run more in a point


def test_a_sweep_of_faithful_runs_says_nothing_of_fidelity(tmp_path):
    sweep(tmp_path)
    path, _ = report.write_report(tmp_path, metrics_of=lambda run: None)
    assert "Not faithful" not in path.read_text()


def test_one_runs_summary_says_it_was_not_faithful(tmp_path):
    from testbed.analysis import runreport

    d = sweep(tmp_path)[0]
    path, _ = runreport.write(load_run(d))
    assert "Not faithful" not in path.read_text()
    mark_unfaithful(d)
    path, _ = runreport.write(load_run(d))
    assert "**Not faithful to its time scale**: 3 of 10 plans applied" in path.read_text()
