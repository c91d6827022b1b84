"""testbed.analysis.decide: its statistics, its plan, the stage-2 sweep files it writes for a
finished sweep, and its command line (PLAN, JUDGE, bad input)."""

import json

import numpy as np
import pytest

from testbed.analysis import decide, decidesweep, stats
from testbed.files import sweepstate
from testbed.sweep import file as sweepfile
from testbed.sweep.rundir import plan_dict
from tests.unit.test_decide_error_rate import fig2
from tests.unit.test_sweep_synthetic import result_doc, write_run


def test_t_distribution_matches_the_table():
    for df in (1, 2, 3, 4, 10, 30):
        assert stats.t_sf2(stats.t975(df), df) == pytest.approx(0.05, abs=2e-4)
        assert stats.t_quantile(0.975, df) == pytest.approx(stats.t975(df), abs=2e-3)
    assert stats.t_quantile(0.975, 1e6) == pytest.approx(1.959964, abs=1e-4)
    assert stats.t_cdf(0.0, 5) == pytest.approx(0.5)
    assert stats.t_quantile(0.025, 7) == pytest.approx(-stats.t_quantile(0.975, 7))


def test_welch():
    t, df, p = stats.welch([1.0, 2.0, 3.0], [4.0, 5.0, 7.0])  # scipy: -3.1623, 3.448, 0.0419
    assert (t, df, p) == pytest.approx((-3.16228, 3.44828, 0.041915), rel=1e-4)
    assert stats.welch([1.0, 1.0], [1.0, 1.0])[2] == 1.0
    assert stats.welch([2.0, 2.0], [1.0, 1.0])[2] == 0.0
    with pytest.raises(ValueError):
        stats.welch([1.0], [1.0, 2.0])


def test_holm_steps_down_and_stops_at_the_first_it_keeps():
    out = decide.holm([0.04, 0.001, 0.015, 0.5], 0.05)
    assert [t for t, _ in out] == pytest.approx([0.05 / 2, 0.05 / 4, 0.05 / 3, 0.05])
    assert [r for _, r in out] == [False, True, True, False]
    assert decide.holm([], 0.05) == []


def test_runs_for_power_is_the_fewest_with_the_power():
    n = decide.runs_for_power(1.0, 0.04, 0.8)
    assert n is not None and decide.power_of(n, 1.0, 0.04) >= 0.8
    assert decide.power_of(n - 1, 1.0, 0.04) < 0.8
    assert decide.runs_for_power(0.01, 0.04, 0.8) is None  # beyond MAX_PLAN_RUNS
    assert decide.runs_for_power(0.0, 0.04, 0.8) is None


def grid_data(rng, runs=3, sd=60.0):
    """Paper-like points (teams 1-4, ranges 5 and 20 m, lasers 2 and 1.5 m)."""
    out = {}
    for la in (2.0, 1.5):
        for c in (5.0, 20.0):
            for n in (1, 2, 3, 4):
                mean = 3000 / n + 40 * n + (5 if c == 5.0 else 0) + (2.0 - la) * 400
                out[(la, c, n)] = tuple(rng.normal(mean, sd, runs))
    return out


def test_the_plan_keeps_the_budget_and_names_what_it_leaves():
    data = grid_data(np.random.default_rng(1))
    comps = decide.comparisons(fig2(data))
    assert {c.claim for c in comps} == set(decide.CLAIMS)
    full = decide.plan(comps, data)
    capped = decide.plan(comps, data, budget_runs=100)
    assert capped.total_runs <= 100 < full.total_runs
    left = [p for p in capped.items if p.runs and not p.in_budget]
    assert left  # named, with the runs each would need
    team = [p for p in full.items if p.comparison.claim == "team"]
    assert all(p.decided and p.stage1.verdict == decide.HOLDS for p in team)  # 1 robot: far
    walls = {pt: 10.0 * pt[2] for pt in data}
    timed = decide.plan(comps, data, wall_s=walls, budget_s=3600)
    assert timed.total_wall_s <= 3600
    for pt, n in full.point_runs.items():  # a point runs the most its comparisons need
        assert n == max(p.runs for p in full.items if p.in_budget
                        and pt in (p.comparison.more, p.comparison.fewer))  # fmt: skip


def write_sweep(out, rng, spec, mean_of, wall=lambda n: 20.0 * n):
    """A finished sweep of `spec` with sweep.json, steps drawn around mean_of(config)."""
    runs = sweepfile.expand(spec)
    for run in runs:
        c = run.config
        steps = float(rng.normal(mean_of(c), 60.0))
        doc = result_doc(c, [round(steps)] * c.robots, round(steps) + 1)
        doc["wall_time_s"] = wall(c.robots)
        write_run(out, run, doc)
    state = sweepstate.SweepState(
        spec=spec.to_dict(),
        runs=tuple(sweepstate.SweepRun(r.run_id, r.index, plan_dict(r.config), {"status": "done"})
                   for r in runs),
    )  # fmt: skip
    sweepstate.write(out, state)
    return runs


def paper_mean(c):
    return (
        3000 / c.robots
        + 40 * c.robots
        + (30 if c.comm_range == 5.0 else 0)
        + (2.0 - c.laser_range) * 400
    )


STAGE1 = dict(robots=(1, 2, 3, 4), comm_range=(5.0, 20.0), laser_range=(2.0, 1.5), runs=3,
              time_scale_by_robots=((1, 10.0), (2, 8.0), (3, 5.0), (4, 5.0)), max_steps=6000,
              capture=True, seed=7)  # fmt: skip


def test_plan_writes_stage_two_sweep_files_with_new_seeds(tmp_path, capsys):
    stage1 = tmp_path / "paper"
    planned = write_sweep(stage1, np.random.default_rng(3), sweepfile.SweepSpec.of(**STAGE1),
                          paper_mean)  # fmt: skip
    out = tmp_path / "stage2"
    assert decidesweep.main(["PLAN", str(stage1), "--budget-runs", "300", "--out", str(out)]) == 0
    screen = capsys.readouterr().out
    print(screen)
    assert "Stage 2:" in screen and "Holm" in screen and "testbed sweep" in screen
    assert len(screen.splitlines()) <= 60
    files = sorted(out.glob("stage2-*.toml"))
    assert files
    old_seeds = {r.config.seed for r in planned}
    total = 0
    for f in files:
        spec = sweepfile.load(f)  # the sweep's own parser takes it
        runs = sweepfile.expand(spec)
        total += len(runs)
        assert not old_seeds & {r.config.seed for r in runs}
        for r in runs:
            assert r.config.max_steps == 6000 and r.config.capture
            assert r.config.time_scale == dict(STAGE1["time_scale_by_robots"])[r.config.robots]
    assert 0 < total <= 300
    assert f"{total} runs" in screen


def test_judge_reads_stage_two_and_says_what_changed(tmp_path, capsys):
    rng = np.random.default_rng(4)
    stage1 = tmp_path / "paper"
    write_sweep(stage1, rng, sweepfile.SweepSpec.of(**STAGE1), paper_mean)
    out = tmp_path / "stage2"
    assert decidesweep.main(["PLAN", str(stage1), "--budget-runs", "300", "--out", str(out)]) == 0
    dirs = []
    for f in sorted(out.glob("stage2-*.toml")):
        d = out / f.stem
        write_sweep(d, rng, sweepfile.load(f), paper_mean)
        dirs.append(str(d))
    capsys.readouterr()
    assert decidesweep.main(["JUDGE", str(stage1), *dirs, "--budget-runs", "300"]) == 0
    text = capsys.readouterr().out
    assert "Team work beats one robot" in text and "p = " in text and "alpha" in text
    assert "(stage 1: undecided)" in text  # a comparison stage 2 decided


@pytest.mark.parametrize(
    "argv, says",
    [
        (["PLAN", "{tmp}/none"], "not a directory"),
        (["PLAN", "{tmp}"], "no finished runs"),
        (["PLAN", "{sweep}", "--alpha", "1.5"], "--alpha"),
        (["PLAN", "{sweep}", "--power", "nan"], "--power"),
        (["PLAN", "{sweep}", "--budget-runs", "-1"], "--budget-runs"),
        (["JUDGE", "{sweep}"], "stage-2"),
        (["PLAN", "{sweep}", "--budget-minutes", "10"], "wall_time_s"),
    ],
)
def test_bad_input_is_one_line_and_status_2(tmp_path, capsys, argv, says):
    sweep = tmp_path / "s"
    write_sweep(sweep, np.random.default_rng(5), sweepfile.SweepSpec.of(**STAGE1), paper_mean,
                wall=lambda n: None)  # fmt: skip
    (tmp_path / "empty").mkdir()
    argv = [a.format(tmp=tmp_path / "empty", sweep=sweep) for a in argv]
    assert decidesweep.main(argv) == 2
    err = capsys.readouterr().err
    assert says in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_a_run_without_sweep_json_is_refused_in_one_line(tmp_path, capsys):
    sweep = tmp_path / "s"
    write_sweep(sweep, np.random.default_rng(6), sweepfile.SweepSpec.of(**STAGE1), paper_mean)
    (sweep / "sweep.json").write_text(json.dumps({"format": 99}))
    assert decidesweep.main(["PLAN", str(sweep), "--out", str(tmp_path / "o")]) == 2
    assert "format 99" in capsys.readouterr().err


def test_testbed_decide_runs_it(tmp_path):
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-m", "testbed", "decide", "PLAN",
                           str(tmp_path / "none")], capture_output=True, text=True)  # fmt: skip
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert done.stderr.strip() == f"decide: {tmp_path / 'none'}: not a directory"
