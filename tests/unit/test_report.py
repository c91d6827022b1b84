"""Report verdicts on synthetic data whose answer is known, and the report end to end."""

import csv
import json
import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest

from testbed.analysis import report, sweepinfo, tables, verdicts
from testbed.analysis.figures import Tables
from testbed.analysis.rows import MeanRange, Spread
from testbed.analysis.runs import DEFAULT_VARIANT, load_runs
from testbed.analysis.tables import Fig2Row, PlanCauseRow, RoutingMeans, RoutingRow, RoutingRun
from testbed.analysis.verdicts import FAILS, HOLDS, NO_DATA, PARTLY, TOO_FEW
from testbed.sweep import file as sweepfile
from tests.unit.test_sweep_synthetic import make_sweep, result_doc, timer_plans, write_run

REPO = Path(__file__).resolve().parents[2]


def rows(fn, robots=(1, 2, 3, 5, 8, 10), comms=(5.0, 20.0), lasers=(2.0, 1.5), noise=0.01):
    """fig2 rows as tables.fig2_rows makes them, each point three runs of mean fn(...) that
    differ by +-`noise` of it."""
    out = []
    for la in lasers:
        for c in comms:
            for n in robots:
                m = fn(n, c, la)
                steps = [m * (1 - noise), m, m * (1 + noise)]
                out.append(Fig2Row(*DEFAULT_VARIANT, la, c, n, Spread.of(steps), tuple(steps), ()))
    return out


def one_run(row):
    """The fig2 row as a point of a single run: no spread, no interval."""
    return replace(row, steps=replace(row.steps, ci_low=None, ci_high=None, std=None, n=1))


def plans(robots, timer=0, request=0, start=0):
    """A plan-cause row of a run of `robots` with those counts."""
    return PlanCauseRow("r", *DEFAULT_VARIANT, robots, 5.0, 2.0, start, timer, request)


def paper(n, c, la):
    return (1200 / n + 40 * n) * (1 + 4 / c) * (2 / la)


def test_all_section_5_1_claims_hold_on_the_papers_shape():
    fig2 = rows(paper)
    for f in (
        verdicts.verdict_team_beats_one,
        verdicts.verdict_fall_then_rise,
        verdicts.verdict_smaller_range,
        verdicts.verdict_shorter_laser,
    ):
        v = f(fig2)
        assert v.verdict == HOLDS, (v.claim, v.evidence)
        assert v.evidence


def test_claims_fail_when_the_data_says_otherwise():
    # more robots only get in each other's way; range and laser do not matter
    fig2 = rows(lambda n, c, la: 100.0 * n)
    assert verdicts.verdict_team_beats_one(fig2).verdict == FAILS
    assert verdicts.verdict_fall_then_rise(fig2).verdict == FAILS
    assert verdicts.verdict_smaller_range(fig2).verdict == FAILS
    assert verdicts.verdict_shorter_laser(fig2).verdict == FAILS


def test_a_rise_or_a_range_effect_within_the_noise_does_not_hold():
    # The paper's shape, but runs that differ by +-30%: the rise at 8-10 robots and the
    # range effect are smaller than the spread of three runs.
    fig2 = rows(paper, noise=0.3)
    rise = verdicts.verdict_fall_then_rise(fig2)
    assert rise.verdict == FAILS
    assert all("within the noise" in e for e in rise.evidence)
    assert any("runs per point would resolve it" in e for e in rise.evidence)
    assert verdicts.verdict_smaller_range(fig2).verdict == FAILS
    assert "within the noise" in verdicts.verdict_smaller_range(fig2).evidence[0]
    # The same shape with tight runs holds.
    assert verdicts.verdict_fall_then_rise(rows(paper)).verdict == HOLDS


def test_one_run_per_point_is_too_few_runs_to_decide_not_a_failure():
    # The short sweep's case: one run per point. Whatever the means say, the noise-aware
    # claims cannot be decided, and the report must not say they do not hold.
    for shape in (paper, lambda n, c, la: 100.0 * n):
        fig2 = [one_run(r) for r in rows(shape)]
        v = verdicts.verdict_fall_then_rise(fig2)
        assert v.verdict == TOO_FEW
        assert all("so the noise is unknown -> too few runs" in e for e in v.evidence)
        v = verdicts.verdict_smaller_range(fig2)
        assert v.verdict == TOO_FEW
        assert all(e.endswith("-> too few runs") for e in v.evidence)
    # the claims decided on means say that they compare single runs
    v = verdicts.verdict_team_beats_one(fig2)
    assert any("rest on one run" in e for e in v.evidence)


def test_a_group_with_one_run_points_is_left_undecided_beside_decided_ones():
    fig2 = rows(paper)
    one = [one_run(r) for r in rows(paper, comms=(7.0,))]
    v = verdicts.verdict_fall_then_rise(fig2 + one)
    assert v.verdict == HOLDS  # decided where it can be
    assert sum("too few runs" in e for e in v.evidence) == 2  # the two lasers at 7 m


def test_fig2_csv_leaves_the_spread_of_a_one_run_point_empty(tmp_path):
    spec = sweepfile.SweepSpec.of(robots=(1, 2), comm_range=(5.0,), laser_range=(2.0,), runs=1)
    make_sweep(tmp_path, spec)
    report.write_report(tmp_path, metrics_of=lambda run: None)
    with (tmp_path / "figures" / "fig2.csv").open() as f:
        rows_ = list(csv.DictReader(f))
    assert [(r["n"], r["std"], r["ci_low"], r["ci_high"]) for r in rows_] == [("1", "", "", "")] * 2
    saved = json.loads((tmp_path / "figures" / "fig2.json").read_text())
    assert all(r["std"] is None for r in saved)


def test_partly_when_only_some_groups_agree():
    # the claim holds at range 5 but not at range 20
    def fn(n, c, la):
        return paper(n, c, la) if c == 5.0 else 100.0 * n

    assert verdicts.verdict_team_beats_one(rows(fn)).verdict == PARTLY
    # shorter laser needs more steps everywhere, but the ratio changes with team size
    v = verdicts.verdict_shorter_laser(rows(lambda n, c, la: 100 + (n if la == 1.5 else 0) * 50))
    assert v.verdict == PARTLY
    assert any("varies" in e for e in v.evidence)


def zigzag_ratio(n, c, la):
    """The shorter laser needs 1.2 or 1.8 times the steps, alternating with team size: a
    ratio whose CV over team sizes is 0.2."""
    return 1000.0 * ((1.2 if (1, 2, 3, 5, 8, 10).index(n) % 2 else 1.8) if la == 1.5 else 1.0)


def test_a_ratio_that_varies_beyond_the_noise_varies_and_within_it_is_undecided():
    tight = verdicts.verdict_shorter_laser(rows(zigzag_ratio, noise=0.01))
    assert tight.verdict == PARTLY
    assert all("CV 0.20" in e and "-> varies" in e for e in tight.evidence if e.startswith("range"))
    # The same means from runs that differ by +-30%: a CV of 0.2 is within their noise.
    # Its headline names that cause, not "too few runs" (each point has its runs).
    loose = verdicts.verdict_shorter_laser(rows(zigzag_ratio, noise=0.3))
    assert loose.verdict == verdicts.WITHIN_NOISE
    ranges = [e for e in loose.evidence if e.startswith("range")]
    assert len(ranges) == 2 and all("-> within the noise" in e for e in ranges)


def test_a_ratio_shown_the_same_at_some_ranges_holds_and_says_where_it_is_undecided():
    fig2 = rows(paper, comms=(5.0,)) + rows(paper, comms=(20.0,), noise=0.3)
    v = verdicts.verdict_shorter_laser(fig2)
    assert v.verdict == HOLDS
    assert "the same ratio is shown at 1 of 2 ranges and undecided at the others" in v.evidence


def test_the_same_ratio_needs_runs_to_be_decided():
    fig2 = [one_run(r) for r in rows(paper)]
    v = verdicts.verdict_shorter_laser(fig2)
    assert v.verdict == TOO_FEW
    assert any("rest on one run" in e for e in v.evidence)
    assert all(e.endswith("-> too few runs)") for e in v.evidence if e.startswith("range"))


def test_the_noise_band_is_the_same_for_the_same_runs():
    fig2 = rows(zigzag_ratio, noise=0.1)
    assert verdicts.verdict_shorter_laser(fig2).evidence == (
        verdicts.verdict_shorter_laser(fig2).evidence
    )


def test_not_enough_data():
    one_point = rows(paper, robots=(3,), comms=(5.0,), lasers=(2.0,))
    for f in (
        verdicts.verdict_team_beats_one,
        verdicts.verdict_fall_then_rise,
        verdicts.verdict_smaller_range,
        verdicts.verdict_shorter_laser,
    ):
        assert f(one_point).verdict == NO_DATA
    assert verdicts.verdict_single_robot_timer([]).verdict == NO_DATA
    assert verdicts.verdict_requests_grow([plans(3, request=4)]).verdict == NO_DATA
    # two team sizes are not enough to see a fall and a rise
    assert verdicts.verdict_fall_then_rise(rows(paper, robots=(1, 5))).verdict == NO_DATA


def test_section_5_2_verdicts():
    alone = [plans(1, timer=40, request=0, start=1)]
    assert verdicts.verdict_single_robot_timer(alone).verdict == HOLDS
    mixed = [plans(1, timer=10, request=10, start=1)]
    v = verdicts.verdict_single_robot_timer(mixed)
    assert v.verdict == FAILS and "50%" in v.evidence[0]
    growing = [plans(n, request=3 * n + k) for n in (1, 2, 5, 10) for k in (0, 1)]
    assert verdicts.verdict_requests_grow(growing).verdict == HOLDS
    shrinking = [plans(n, request=30 - 3 * n) for n in (1, 2, 5, 10)]
    assert verdicts.verdict_requests_grow(shrinking).verdict == FAILS
    noisy = [plans(n, request=r) for n, r in ((1, 0), (2, 5), (3, 2), (4, 6))]
    assert verdicts.verdict_requests_grow(noisy).verdict == PARTLY


def test_spearman():
    assert verdicts.spearman([1, 2, 3], [10, 20, 30]) == pytest.approx(1.0)
    assert verdicts.spearman([1, 2, 3], [3, 2, 1]) == pytest.approx(-1.0)
    assert verdicts.spearman([1, 2, 3, 4], [1, 1, 2, 2]) == pytest.approx(0.894, abs=1e-3)
    assert verdicts.spearman([1, 2], [5, 5]) is None


def test_report_end_to_end(tmp_path):
    # Three runs a point (+-3 steps): the rise and the range effect stand out of the noise.
    spec = sweepfile.SweepSpec.of(
        robots=(1, 2, 5, 10), comm_range=(5.0, 20.0), laser_range=(2.0, 1.5), runs=3
    )
    make_sweep(tmp_path, spec)
    path, vs = report.write_report(tmp_path, metrics_of=lambda run: None)
    assert [v.verdict for v in vs] == [HOLDS] * 6
    text = path.read_text()
    assert path == tmp_path / "report.md"
    assert "![fig2a](figures/fig2a.png)" in text and "![fig4](figures/fig4.png)" in text
    assert "| 5.1 | Team work beats one robot" in text
    assert "No run has packet captures" in text
    named = re.findall(r"numbers: `(figures/[^`]+)`", text)
    assert "figures/fig2.csv" in named and "figures/fig4.csv" in named
    assert all((tmp_path / f).is_file() for f in named)  # every file the report names exists
    saved = json.loads((tmp_path / "figures" / "verdicts.json").read_text())
    assert [v["verdict"] for v in saved] == [HOLDS] * 6
    assert "## Ablation" not in text  # one variant: no ablation section
    fig2 = (tmp_path / "figures" / "fig2.csv").read_text().splitlines()
    assert fig2[0].startswith("coordination,start_placement,") and "ci_low" in fig2[0]


def test_report_of_an_ablation_sweep(tmp_path):
    # paper coordination rises at 10 robots; ours does not (a made-up answer to find).
    spec = sweepfile.SweepSpec.of(robots=(1, 2, 5, 10), comm_range=(20.0,), laser_range=(2.0,),
                               coordination=("paper", "ours"), runs=3)  # fmt: skip
    for run in sweepfile.expand(spec):
        c = run.config
        n = c.robots
        steps = 1200 / n + (40 * n if c.coordination == "paper" else 0) + (run.index - 2)
        plans = {k: timer_plans(int(steps)) for k in range(1, n + 1)}
        if n == 10:  # requests at the start and the end of the run, as in the paper's Fig. 4(d)
            plans[1] = plans[1] + [{"step": 2, "cause": "request"},
                                   {"step": int(steps) - 2, "cause": "request"}]  # fmt: skip
        write_run(tmp_path, run, result_doc(c, [int(steps)] * n, int(steps), plans))
    path, vs = report.write_report(tmp_path, metrics_of=lambda run: None)
    text = path.read_text()
    assert "## Ablation: what makes big teams slow" in text
    assert "| paper, corner | " in text and "| ours, corner | " in text
    assert "- coordination: paper, corner rises and ours, corner does not" in text
    assert "- start placement: changes nothing alone" in text
    thirds = (tmp_path / "figures" / "ablation_thirds.csv").read_text().splitlines()
    assert thirds[0].split(",")[:7] == [
        "coordination",
        "start_placement",
        "run",
        "steps",
        "request_start",
        "request_middle",
        "request_end",
    ]
    assert len(thirds) == 1 + 2 * 3  # both variants' three runs of 10 robots
    assert all(line.split(",")[4:7] == ["1", "0", "1"] for line in thirds[1:])
    assert (tmp_path / "figures" / "ablation_fig4.png").is_file()


def test_report_counts_excluded_runs(tmp_path):
    spec = sweepfile.SweepSpec.of(robots=(1, 2), comm_range=(5.0,), laser_range=(2.0,), runs=1)
    runs = sweepfile.expand(spec)
    write_run(tmp_path, runs[0])
    doc = result_doc(runs[1].config, [None, None], 40, {1: timer_plans(40)}, "robot_crashed")
    write_run(tmp_path, runs[1], doc)
    path, vs = report.write_report(tmp_path, metrics_of=lambda run: None)
    text = path.read_text()
    assert "Finished runs: 2 (complete: 1, robot_crashed: 1)" in text
    assert vs[0].verdict == NO_DATA  # the only team run crashed


def test_cli_not_a_sweep_directory(tmp_path):
    r = subprocess.run(
        [sys.executable, "-m", "testbed.analysis.report", str(tmp_path / "nothing")],
        capture_output=True,
        text=True,
        cwd=REPO,
    )
    assert r.returncode == 2
    assert len(r.stderr.strip().splitlines()) == 1 and "DIR" in r.stderr


def routing_run(run="a", robots=1, scale=1.0, tcp=True, pdf=None, difference=None, dropped=None):
    """A routing_runs row with the given numbers (the others empty)."""
    return RoutingRun(
        run=run, robots=robots, comm_range=5.0, laser_range=2.0, loss_pct=0.0, delay_ms=0.0,
        time_scale=scale, tcp_emulated=tcp, overhead_packets=None, pdf=pdf,
        delay_ms_median=None, throughput_bps=None, delay_ms_median_emulated=None,
        control_tx_packets=None, tx_packets=None, daemon_tx_packets=None,
        daemon_relative_difference=difference, capture_dropped_packets=dropped,
    )  # fmt: skip


def test_daemon_section_names_the_captures_kernel_drops():
    runs = [
        routing_run("a", difference=0.0, dropped=0),
        routing_run("b", difference=0.012, dropped=30),
        routing_run("c", difference=0.001, dropped=4),
    ]
    first, second = report._daemon_section(runs)
    assert "2 of 3 runs agree within 1%; largest difference 1.20% (b)" in first
    assert "Captures of 2 runs lost packets in the kernel" in second
    assert "34 in all, at most 30 (b)" in second
    assert report._daemon_section(runs[:1]) == [report._daemon_section(runs[:1])[0]]


def test_sweep_section_tells_time_scale_changes_from_concurrency_changes(tmp_path):
    state = {
        "jobs": 1,
        "time_scale_factor": {"1": 0.85, "10": 0.72},
        "backoffs": [
            {"run": "a", "deadline_miss_fraction": 0.02, "robots": 1, "time_scale_factor": 0.85},
            {"run": "b", "deadline_miss_fraction": 0.03, "jobs": 1},
        ],
    }
    (tmp_path / "sweep.json").write_text(json.dumps(state))
    text = " ".join(sweepinfo.lines(tmp_path, []))
    assert "lowered its concurrency 1 time(s)" in text and "now 1 job(s) at most" in text
    assert "changed a team size's time scale 1 time(s)" in text
    assert "0.85 for 1, 0.72 for 10" in text


def test_sweep_section_counts_a_lowered_cpu_limit_as_a_concurrency_change(tmp_path):
    state = {
        "jobs": 2,
        "cpu_limit": 1.2,
        "backoffs": [{"run": "a", "deadline_miss_fraction": 0.0, "cpu_limit": 1.2}],
    }
    (tmp_path / "sweep.json").write_text(json.dumps(state))
    text = " ".join(sweepinfo.lines(tmp_path, []))
    assert "lowered its concurrency 1 time(s)" in text
    assert "now 2 job(s) at most, within 1.2 cores" in text


def test_sweep_section_gives_short_stalls_in_their_own_precision(tmp_path):
    # 0.076 s of host stalls was reported as "0 s in all"
    spec = sweepfile.SweepSpec.of(robots=(2,), comm_range=(5.0,), laser_range=(2.0,), runs=1)
    run = sweepfile.expand(spec)[0]
    doc = result_doc(run.config, [90, 95], 100)
    doc.update(deadlines_missed=3, host_stalls={"events": 2, "stalled_s": 0.076,
                                                "deadlines_missed": 3})  # fmt: skip
    write_run(tmp_path, run, doc)
    text = " ".join(sweepinfo.lines(tmp_path, load_runs(tmp_path)))
    assert "0.076 s in all" in text
    assert [sweepinfo.seconds(x) for x in (0.0, 0.076, 1.234, 9.94, 12.6, 130.2)] == [
        "0", "0.076", "1.2", "9.9", "13", "130",
    ]  # fmt: skip


def test_routing_rows_carry_their_time_scales_and_whether_tcp_kept_emulated_time():
    def run(robots, scale, tcp, pdf):
        return routing_run(f"{robots}-{scale}", robots, scale, tcp, pdf)

    rows = tables.routing_rows([run(1, 30, True, 1.0), run(10, 6, False, 0.78),
                                run(10, 6, True, 0.7)])  # fmt: skip
    by = {r.robots: r for r in rows}
    assert by[1].time_scales == (30,) and by[1].tcp_emulated is True
    assert by[10].time_scales == (6,) and by[10].tcp_emulated is False


def _routing_row(robots, scale, tcp):
    means = RoutingMeans(**{m: MeanRange(1.0) for m in tables.ROUTING_FIELDS})
    return RoutingRow(5.0, robots, 3, means, (scale,), tcp)


def test_the_routing_table_marks_pdf_and_delay_of_runs_whose_tcp_was_not_dilated():
    rows = [_routing_row(1, 30.0, True), _routing_row(10, 6.0, False)]
    text = "\n".join(report._routing_section(Tables(routing=rows)))
    lines = [line for line in text.splitlines() if line.startswith("| 5 |")]
    assert "†" not in lines[0] and lines[1].count("†") == 2  # PDF and emulated delay
    assert "† Ran dilated without TCP's retransmission timer dilated" in text
    assert ": 10 robots at 5 m. A retransmission there waited K times longer" in text


def test_the_routing_table_says_tcp_was_dilated_when_it_was_at_every_scale():
    rows = [_routing_row(1, 30.0, True), _routing_row(10, 6.0, True)]
    text = "\n".join(report._routing_section(Tables(routing=rows)))
    assert "†" not in text
    assert "TCP's timers were dilated with each run's time scale" in text
    # One time scale: nothing to say about comparing across scales.
    rows = [_routing_row(1, 6.0, False), _routing_row(10, 6.0, False)]
    text = "\n".join(report._routing_section(Tables(routing=rows)))
    assert "†" not in text and "dilated" not in text
