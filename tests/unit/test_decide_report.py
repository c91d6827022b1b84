"""The deciding design read by the report and by `testbed compare`: synthetic sweep
directories (result.json and sweep.json as `testbed run` and `testbed sweep` write them, via
tests.unit.test_decide's writer), stage 2 planned by `testbed decide PLAN`
and its sweeps written from the files it planned; then `testbed report` and the claims'
comparison of two sweeps. The large teams (12, 15, 20) are a second stage-1 sweep, as
testbed/experiments/paper-large-teams.toml makes one."""

import json
import re
import shutil
import types

import numpy as np
import pytest

from common.errors import UsageError
from testbed.analysis import claimcompare, decide, decidereport, decidesweep, plots, report
from testbed.analysis import scalecompare as sc
from testbed.sweep import file as sweepfile
from tests.unit.test_decide import STAGE1, paper_mean, write_sweep

LARGE = dict(STAGE1, robots=(12, 15, 20), comm_range=(5.0, 20.0),
             time_scale_by_robots=((12, 5.0), (15, 5.0), (20, 5.0)))  # fmt: skip


def mean_of(range_effect: float):
    """paper_mean (its fewest steps near 9 robots, so teams of 1-4 never rise and teams of
    12-20 do) with the smaller range's extra steps."""
    return lambda c: paper_mean(c) + (range_effect if c.comm_range == 5.0 else 0.0)


def deciding_sweep(root, seed, range_effect=120.0, budget="400", stage2_files=None):
    """A deciding sweep in `root`: paper/ (teams 1-4), paper-large-teams/, paper-stage2/ with
    plan.json and its sweeps (the first `stage2_files` of them; None: all)."""
    rng = np.random.default_rng(seed)
    mean = mean_of(range_effect)
    stage1 = root / "paper"
    write_sweep(stage1, rng, sweepfile.SweepSpec.of(**dict(STAGE1, seed=seed)), mean)
    large = root / "paper-large-teams"
    write_sweep(large, rng, sweepfile.SweepSpec.of(**dict(LARGE, seed=seed)), mean)
    argv = ["PLAN", str(stage1), "--with", str(large), "--budget-runs", budget]
    assert decidesweep.main(argv) == 0
    out = root / "paper-stage2"
    files = sorted(out.glob("stage2-*.toml"))
    for f in files[:stage2_files]:
        write_sweep(out / f.stem, rng, sweepfile.load(f), mean)
    return stage1


@pytest.fixture(scope="module")
def decided_sweep(tmp_path_factory):
    """A finished deciding sweep whose budget leaves comparisons undecided, reported."""
    root = tmp_path_factory.mktemp("deciding")
    stage1 = deciding_sweep(root, 11, budget="120")
    path, vs = report.write_report(stage1, metrics_of=lambda run: None)
    return types.SimpleNamespace(
        stage1=stage1, text=path.read_text(), vs=vs,
        decided=decidesweep.load_decided(root / "paper-stage2"),
    )  # fmt: skip


def _row(text: str, first_cell: str) -> str:
    rows = [r for r in text.splitlines() if r.startswith(f"| {first_cell} |")]
    assert len(rows) == 1, (first_cell, rows)
    return rows[0]


def test_without_a_stage_2_the_report_is_the_single_sweeps(tmp_path):
    stage1 = tmp_path / "paper"
    write_sweep(stage1, np.random.default_rng(2), sweepfile.SweepSpec.of(**STAGE1),
                mean_of(120.0))  # fmt: skip
    # A plan elsewhere (not PLAN's default beside the sweep) is not taken up either.
    assert decidesweep.main(["PLAN", str(stage1), "--out", str(tmp_path / "x" / "plan")]) == 0
    path, _ = report.write_report(stage1, metrics_of=lambda run: None)
    text = path.read_text()
    assert "## The paper's claims against these runs" in text
    assert "stage 2" not in text.lower() and "deciding" not in text.lower()
    assert not (stage1 / "figures" / "decided.json").exists()
    assert not list((stage1 / "figures").glob("fig2-decided-*"))
    assert decidereport.section(None, None, [], [], None) == []
    # an earlier report's stage-2 files go with the stage 2 they came from
    (stage1 / "figures" / "decided.json").write_text("{}")
    (stage1 / "figures" / "fig2-decided-a.png").write_bytes(b"")
    report.write_report(stage1, metrics_of=lambda run: None)
    assert not (stage1 / "figures" / "decided.json").exists()
    assert not list((stage1 / "figures").glob("fig2-decided-*"))


def test_the_report_shows_each_claims_deciding_verdict_test_and_error_rate(decided_sweep):
    text, d = decided_sweep.text, decided_sweep.decided
    assert "## The claims decided (stage 2 of the deciding design)" in text
    assert "Welch's two-sample t test" in text and "Holm" in text
    assert f"at most {d.plan.alpha:g} ({d.plan.alpha1:g} at stage 1" in text
    for key, claim in decide.CLAIMS.items():
        mine = [x for x in d.decisions if x.planned.comparison.claim == key]
        row = _row(text, claim)
        assert f"**{decide.claim_verdict(mine)}**" in row and f"at most {d.plan.alpha:g}" in row
        done = sum(x.final != decide.UNDECIDED for x in mine)
        assert f"| {done} of {len(mine)} |" in row
    tested = [x for x in d.decisions if x.stage2 is not None]
    assert tested
    for x in tested:  # its runs, test, p, Holm-adjusted p and alpha, as judged
        t = x.stage2
        row = _row(text, x.planned.comparison.where)
        assert (
            f"| {t.runs[0]}+{t.runs[1]} | {t.diff:+.0f} | {t.t:.2f} ({t.df:.1f}) | "
            f"{decide._p(t.p)} | {decide._p(t.p_holm)} | {decide._p(t.alpha)} |"
        ) in row
        assert f"**{x.final}**" in row
        assert ("changed; stage 1:" in row) == x.changed
        assert (t.p_holm <= d.plan.alpha2) == (t.verdict != decide.UNDECIDED)
    assert d.done_runs == d.plan.total_runs and "not finished" not in text
    page = (decided_sweep.stage1 / "report.html").read_text()
    assert "<h2>The claims decided (stage 2 of the deciding design)</h2>" in page
    doc = json.loads((decided_sweep.stage1 / "figures" / "decided.json").read_text())
    assert doc == json.loads(json.dumps(decidereport.decided_doc(d)))


def test_a_verdict_changed_by_the_deciding_runs_is_marked(decided_sweep):
    text, d = decided_sweep.text, decided_sweep.decided
    # the report's 3-run verdicts are this sweep's (teams 1-4), not the large teams'
    own = [r for r in decidesweep.paper_rows(d.stage1.runs) if r.robots <= 10]
    marks = {}
    for key, claim in decide.CLAIMS.items():
        mine = [x for x in d.decisions if x.planned.comparison.claim == key]
        before = decidereport.three_run(key, decided_sweep.vs, own)
        after = decide.claim_verdict(mine)
        row = _row(text, claim)
        assert f"| {claim} | {before} | **{after}** |" in row
        marks[key] = "**changed**" in row
        assert marks[key] == (decidereport.category(before) != decidereport.category(after))
    # teams of 1-4 have their fewest steps at 4 (no rise); with 12-20 the rise is tested
    assert marks["rise"] and not marks["team"]
    assert decidereport.category("undecided (1 of 4 comparisons)") == "undecided"
    assert decidereport.category("too few runs to decide") == "undecided"


def test_what_the_budget_left_is_named_with_the_runs_it_needs(decided_sweep):
    text, d = decided_sweep.text, decided_sweep.decided
    left = [x for x in d.decisions if not x.planned.decided and not x.planned.in_budget]
    assert left and d.plan.total_runs <= 120
    assert f"Left undecided by the budget or beyond reach ({len(left)} comparisons):" in text
    for x in left:
        c = x.planned.comparison
        assert f"- {decide.CLAIMS[c.claim]}: {c.where}: needs {x.planned.runs} runs a point" in text
        assert x.final == decide.UNDECIDED


def test_the_rise_takes_teams_past_ten_and_the_other_claims_do_not(decided_sweep):
    comps = decided_sweep.decided.stage1.comps
    rise = [c for c in comps if c.claim == "rise"]
    assert rise and all(c.more[2] == 20 and c.fewer[2] in (12, 15) for c in rise)
    assert all(max(c.more[2], c.fewer[2]) <= 10 for c in comps if c.claim != "rise")
    assert "teams of 12, 15, 20 are beyond the paper's range (1-10)" in decided_sweep.text


def test_fig2_marks_teams_past_ten_as_beyond_the_papers_range(decided_sweep):
    rows = decidereport.fig2_rows(decided_sweep.decided)
    for laser in (2.0, 1.5):
        lines = plots.fig2_lines(rows, laser)
        xs = {p.x: p.beyond for _, pts in lines for p in pts}
        assert xs == {n: n > 10 for n in (1, 2, 3, 4, 12, 15, 20)}
        fig = plots.fig2_figure(rows, laser, "a")
        labels = fig.axes[0].get_legend_handles_labels()[1]
        assert plots.BEYOND_PAPER in labels
    paper_only = [r for r in rows if r.robots <= 10]
    labels = plots.fig2_figure(paper_only, 2.0, "a").axes[0].get_legend_handles_labels()[1]
    assert plots.BEYOND_PAPER not in labels
    figdir = decided_sweep.stage1 / "figures"
    for letter in "ab":
        assert (figdir / f"fig2-decided-{letter}.png").stat().st_size > 0
        assert f"![fig2-decided-{letter}](figures/fig2-decided-{letter}.png)" in decided_sweep.text


def test_an_unfinished_stage_2_says_so(tmp_path):
    stage1 = deciding_sweep(tmp_path, 12, stage2_files=1)
    path, _ = report.write_report(stage1, metrics_of=lambda run: None)
    text = path.read_text()
    d = decidesweep.load_decided(tmp_path / "paper-stage2")
    assert d.done_runs < d.plan.total_runs
    assert f"{d.done_runs} of {d.plan.total_runs} planned runs done" in text
    assert "**stage 2 is not finished**" in text
    for run_dir in (tmp_path / "paper-stage2").glob("stage2-*"):
        if run_dir.is_dir():
            shutil.rmtree(run_dir)
    text = report.write_report(stage1, metrics_of=lambda run: None)[0].read_text()
    assert f"0 of {d.plan.total_runs} planned runs done" in text
    assert "**stage 2 has not run yet**" in text and "not finished" not in text
    assert "| Claim | 3 runs a point | Deciding runs |" not in text and "changed" not in text
    assert not (stage1 / "figures" / "decided.json").exists()
    assert "its stage 2 has not run" in claimcompare.claims_of(stage1).note


def test_a_plan_stage_1_no_longer_gives_is_named_and_not_judged(tmp_path):
    stage1 = deciding_sweep(tmp_path, 13)
    plan = tmp_path / "paper-stage2" / "plan.json"
    doc = json.loads(plan.read_text())
    doc["files"][0]["runs"] += 1  # as if stage 1 had changed since PLAN
    plan.write_text(json.dumps(doc))
    path, _ = report.write_report(stage1, metrics_of=lambda run: None)
    text = path.read_text()
    assert "A plan directory was found but not read:" in text and "plan again" in text
    assert "| Claim | 3 runs a point | Deciding runs |" not in text
    with pytest.raises(UsageError, match="--stage2 .*plan again"):
        report.write_report(stage1, metrics_of=lambda run: None,
                            stage2=tmp_path / "paper-stage2")  # fmt: skip
    assert decidesweep.main(["JUDGE", str(tmp_path / "paper-stage2")]) == 2


def test_judge_reads_the_plan_it_wrote(decided_sweep, capsys):
    capsys.readouterr()
    assert decidesweep.main(["JUDGE", str(decided_sweep.stage1)]) == 0  # the plan beside it
    text = capsys.readouterr().out
    for key, claim in decide.CLAIMS.items():
        mine = [x for x in decided_sweep.decided.decisions if x.planned.comparison.claim == key]
        assert f"{claim}: {decide.claim_verdict(mine)}" in text


def _claims_rows(lines, names):
    """The compare section's deciding table: claim -> (a, b, agree)."""
    out = {}
    for line in lines:
        cells = [c.strip() for c in line.strip("|").split("|")]
        if len(cells) == 5 and cells[0] in decide.CLAIMS.values():
            out[cells[0]] = (cells[1], cells[2], cells[3])
    return out


def test_compare_of_two_deciding_sweeps_says_which_claims_agree(tmp_path):
    a = deciding_sweep(tmp_path / "a", 21)
    b = deciding_sweep(tmp_path / "b", 22)  # other seeds, the same truth
    flipped = deciding_sweep(tmp_path / "c", 23, range_effect=-250.0)  # the range reversed
    ca, cb, cc = (claimcompare.claims_of(x) for x in (a, b, flipped))
    assert ca.decided and cb.decided and cc.decided
    for other in (cb, cc):
        lines = claimcompare.section(ca, other)
        rows = _claims_rows(lines, (ca.name, other.name))
        assert set(rows) == set(decide.CLAIMS.values())
        agree = 0
        for key, claim in decide.CLAIMS.items():
            x, y, said = rows[claim]
            assert (x, y) == (ca.decided[key], other.decided[key])
            cx, cy = decidereport.category(x), decidereport.category(y)
            undecided = decidereport.UNDECIDED in (cx, cy)
            assert said == ("yes" if cx == cy else "one undecided" if undecided else "**no**")
            agree += cx == cy
        summary = [s for s in lines if s.startswith("- Deciding verdicts:")]
        assert summary == [s for s in summary if f"agree on {agree} of 4 claims" in s]
        assert len(summary) == 1
    range_claim = decide.CLAIMS["range"]
    assert cc.decided["range"] == decide.FAILS != ca.decided["range"]
    text = "\n".join(claimcompare.section(ca, cc))
    if ca.decided["range"] == decide.HOLDS:  # two verdicts that contradict
        assert re.search(f"they disagree on [^.]*{re.escape(range_claim)}", text)
    else:
        assert re.search(f"one is undecided on [^.]*{re.escape(range_claim)}", text)
    assert claimcompare.agreement(decide.HOLDS, decide.FAILS) == "**no**"
    assert claimcompare.agreement("undecided (1 of 4 comparisons)", decide.FAILS) == (
        "one undecided"
    )
    assert claimcompare.agreement("too few runs to decide", "undecided (2 of 3)") == "yes"


def test_testbed_compare_adds_the_claims_of_two_plain_sweeps(tmp_path, capsys):
    for name, seed in (("one", 31), ("two", 32)):
        write_sweep(tmp_path / name, np.random.default_rng(seed),
                    sweepfile.SweepSpec.of(**dict(STAGE1, seed=seed)), mean_of(120.0))  # fmt: skip
    args = types.SimpleNamespace(a=str(tmp_path / "one"), b=str(tmp_path / "two"), out=None,
                                 include_unfaithful=False)  # fmt: skip
    assert sc.main(args) == 0
    text = capsys.readouterr().out
    assert "## The paper's claims in both sweeps" in text
    assert "- Deciding verdicts: not compared (one: no stage 2" in text
    assert re.search(r"- The report's verdicts: the two sweeps agree on \d of 6 claims", text)


def test_plan_takes_the_large_teams_beside_it_and_only_its_own_files_and_runs(tmp_path, capsys):
    rng = np.random.default_rng(41)
    stage1, large = tmp_path / "paper", tmp_path / "paper-large-teams"
    write_sweep(stage1, rng, sweepfile.SweepSpec.of(**STAGE1), mean_of(120.0))
    write_sweep(large, rng, sweepfile.SweepSpec.of(**LARGE), mean_of(120.0))
    out = tmp_path / "paper-stage2"
    out.mkdir()
    (out / "stage2-99.toml").write_text("an earlier plan's file\n")
    assert decidesweep.main(["PLAN", str(stage1)]) == 0  # no --with: the one beside it
    assert f"Stage 1: {stage1}, {large}" in capsys.readouterr().out
    assert json.loads((out / "plan.json").read_text())["stage1"] == [
        "../paper",
        "../paper-large-teams",
    ]
    assert not (out / "stage2-99.toml").exists()
    scales = dict(STAGE1["time_scale_by_robots"]) | dict(LARGE["time_scale_by_robots"])
    teams = set()
    for f in sorted(out.glob("stage2-*.toml")):
        spec = sweepfile.load(f)
        for run in sweepfile.expand(spec):  # each team at its own sweep file's time scale
            assert run.config.time_scale == scales[run.config.robots]
            teams.add(run.config.robots)
        write_sweep(out / f.stem, rng, spec, mean_of(120.0))
    assert teams & {12, 15, 20} and teams & {1, 2, 3, 4}
    d = decidesweep.load_decided(out)
    assert d.done_runs == d.plan.total_runs
    assert any(c.more[2] == 20 for c in d.stage1.comps)
    # a run of another plan under a planned run's id (another seed) is not judged
    result = next(out.glob("stage2-*/runs/*/result.json"))
    doc = json.loads(result.read_text())
    doc["config"]["seed"] += 1
    result.write_text(json.dumps(doc))
    assert decidesweep.load_decided(out).done_runs == d.plan.total_runs - 1
