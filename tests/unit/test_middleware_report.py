"""The middlewares' section of the report (the paper's Section 3): per point and middleware
the steps, the survivors, delivery, blocked time and air cost, and the verdict's rule, on a
synthetic sweep with known numbers and on the rule's own cases."""

import pytest

from testbed.analysis import figures, middlewares, report, stats
from testbed.analysis.verdicts import FAILS, HOLDS, TOO_FEW
from testbed.files import routingfile
from testbed.sweep import file as sweepfile
from testbed.sweep.rundir import plan_dict
from tests.unit.test_sweep_synthetic import result_doc, write_run

CAP = 3000
WALL_S = 20.0  # every run's step loop
DURATION_S = 10.0  # the captures' span


def doc(run, stuck_middleware="zeromq-reqrep"):
    """A finished run: the killed robot (rN) leaves no counters; under `stuck_middleware`
    the survivors never finish after a failure and one send is still waiting at the end."""
    c = run.config
    failed = c.battery_failure == "midrun"
    stuck = failed and c.middleware == stuck_middleware
    finish = [CAP if stuck else 400 + 10 * run.index + k for k in range(c.robots)]
    d = result_doc(plan_dict(c), finish, CAP if stuck else max(finish) + 1,
                   status="step_cap" if stuck else "complete")  # fmt: skip
    d["config"]["extra"] = {"middleware": c.middleware, "battery_failure": c.battery_failure}
    if failed:
        d["robots"][f"r{c.robots}"].update(finish_step=None, stopped_step=100, exit_status=-9)
    survivors = c.robots - failed
    d["survivors_finished"] = not stuck
    d["step_loop_wall_s"] = WALL_S
    d["messaging"] = {
        "middleware": c.middleware,
        "team": {
            "robots": survivors, "sent": 100 * survivors, "received": 90 * survivors + run.index,
            "failed": 2 * failed, "duplicates": 0, "late": run.index,
            "blocked_s": WALL_S if stuck else 0.01 * survivors,
            "blocked_max_s": WALL_S if stuck else 0.005, "sending": int(stuck),
            "messages": 90 * survivors, "delay_steps_max": 1,
        },
        "robots": {},
    }  # fmt: skip
    return d


def sweep(tmp_path, runs=2, mws=("nanomsg", "zeromq-reqrep", "dds"), stuck="zeromq-reqrep"):
    spec = sweepfile.SweepSpec.of(
        robots=(2, 5), comm_range=(20.0,), laser_range=(2.0,), runs=runs, time_scale=4.0,
        middleware=mws, battery_failure=("none", "midrun"),
    )  # fmt: skip
    metrics = {}
    for run in sweepfile.expand(spec):
        c = run.config
        write_run(tmp_path, run, doc(run, stuck))
        mw = {"name": c.middleware, "framing": None}  # dds: the captures have no class
        if c.middleware != "dds":
            robot_s = c.robots * DURATION_S * c.time_scale
            mw.update(tx_bytes=500.0 * robot_s, protocol_bytes=50.0 * robot_s)
        metrics[run.run_id] = {"duration_s": DURATION_S, "middleware": mw}
    return lambda run: routingfile.parse(m) if (m := metrics.get(run.run_id)) else None


def rows_by(made):
    return {(r.robots, r.battery_failure, r.middleware): r
            for r in made.tables.middlewares}  # fmt: skip


def test_rows_per_point_and_middleware_with_intervals(tmp_path):
    made = figures.make_all(tmp_path, metrics_of=sweep(tmp_path))
    rows = rows_by(made)
    assert len(rows) == 2 * 2 * 3
    assert [(r.robots, r.battery_failure, r.middleware) for r in
            made.tables.middlewares][:3] == [
        (2, "none", "nanomsg"), (2, "none", "zeromq-reqrep"), (2, "none", "dds")]  # fmt: skip
    plain = rows[(5, "none", "nanomsg")]
    assert plain.n == 2 and plain.left_out == 0
    # finishing steps 400 + 10 k + (0..4): mean 412 then 422 -> 417 with an interval
    p = plain.means
    assert p.steps.mean == pytest.approx(417)
    assert p.steps.ci_low < 417 < p.steps.ci_high
    assert (plain.survivors_finished_runs, plain.survivors_runs) == (2, 2)
    assert p.delivery.mean == pytest.approx(((450 + 1) / 500 + (450 + 2) / 500) / 2)
    assert p.blocked_share.mean == pytest.approx(0.05 / (5 * WALL_S))
    assert p.air_bytes_per_robot_s.mean == pytest.approx(500.0)
    assert p.air_own_share.mean == pytest.approx(0.1)
    # The killed robot is not in the steps; the counters are the survivors'.
    killed = rows[(5, "midrun", "nanomsg")]
    assert killed.means.steps.mean == pytest.approx((410 + 1.5 + 420 + 1.5) / 2)
    assert killed.means.failed.mean == 2 and killed.sending_runs == 0
    stuck = rows[(5, "midrun", "zeromq-reqrep")]
    assert (stuck.survivors_finished_runs, stuck.means.steps.mean) == (0, CAP)
    s = stuck.means
    assert s.blocked_share.mean == pytest.approx(1 / 4) and s.blocked_max_s.mean == WALL_S
    assert stuck.sending_runs == 2
    assert rows[(5, "none", "dds")].means.air_bytes_per_robot_s.mean is None
    # The paper's figures stay on the default middleware without a failure.
    assert [r.steps_per_run for r in made.tables.fig2 if r.robots == 5] == [
        (412, 422)]  # fmt: skip


def test_the_section_table_and_the_verdict_for_a_naive_zeromq_that_stops(tmp_path):
    made = figures.make_all(tmp_path, metrics_of=sweep(tmp_path))
    text = "\n".join(middlewares.section(made.tables.middlewares))
    assert "## Which middleware a team can rely on (the paper's Section 3)" in text
    assert "| 5 | 20 | midrun | zeromq-reqrep | 2 | 0 | 0 of 2 | 3000 [3000, 3000] |" in text
    assert "| 5 | 20 | none | dds | 2 | 0 | 2 of 2 |" in text and "not measured" in text
    assert "**Does the paper's claim hold?** holds: zeromq-reqrep stopped the team, and " \
        "none of nanomsg, dds did." in text  # fmt: skip
    assert "- zeromq-reqrep: holds; survivors finished without the failure 4 of 4" in text
    assert "- nanomsg: does not hold;" in text and "- dds: does not hold;" in text


def test_the_report_has_the_section_only_when_the_middleware_varies(tmp_path):
    path, _ = report.write_report(tmp_path, metrics_of=sweep(tmp_path))
    assert "## Which middleware a team can rely on" in path.read_text()
    assert "Which middleware a team can rely on" in (tmp_path / "report.html").read_text()
    single = tmp_path / "single"
    spec = sweepfile.SweepSpec.of(
        robots=(2,), comm_range=(5.0,), laser_range=(2.0,), middleware="zeromq",
        battery_failure=("none", "midrun"),
    )  # fmt: skip
    for run in sweepfile.expand(spec):
        write_run(single, run, doc(run))
    path, _ = report.write_report(single, metrics_of=lambda run: None)
    assert "Which middleware" not in path.read_text()
    assert figures.make_all(single, metrics_of=lambda run: None).tables.middlewares == []


def test_one_run_per_point_is_too_few_to_decide(tmp_path):
    made = figures.make_all(tmp_path, metrics_of=sweep(tmp_path, runs=1))
    by, paper = middlewares.verdicts(made.tables.middlewares)
    assert {v for v, _ in by.values()} == {TOO_FEW}
    assert paper[0] == TOO_FEW
    assert "fewer than 4 runs in a mode" in by["nanomsg"][1]


def test_a_bounded_middleware_that_stops_refutes_the_papers_reading(tmp_path):
    made = figures.make_all(tmp_path, metrics_of=sweep(tmp_path, runs=2, stuck="nanomsg"))
    by, paper = middlewares.verdicts(made.tables.middlewares)
    assert by["nanomsg"][0] == HOLDS and by["zeromq-reqrep"][0] == FAILS
    assert paper[0] == FAILS


@pytest.mark.parametrize(
    ("without", "failed", "verdict"),
    [
        ((10, 10), (0, 10), HOLDS),  # stops, far beyond the noise
        ((10, 10), (10, 10), FAILS),  # carries on
        ((10, 10), (9, 10), FAILS),  # 90%: carries on
        ((4, 4), (0, 4), HOLDS),  # the fewest runs that can show it: [51%, 100%] vs [0, 49%]
        ((3, 3), (0, 3), TOO_FEW),  # fewer than MIN_RUNS a mode
        ((10, 10), (6, 10), "undecided"),  # between the bounds
        ((5, 10), (0, 10), "undecided"),  # does not finish without the failure either
        ((9, 10), (4, 10), "undecided"),  # under 50%, but within the noise of 90%
    ],
)
def test_the_rule_for_one_middleware(without, failed, verdict):
    assert middlewares.middleware_verdict(without, failed)[0] == verdict


def test_the_papers_reading_from_the_middlewares():
    v = middlewares.paper_verdict
    holds, fails = (HOLDS, ""), (FAILS, "")
    assert v({"zeromq-reqrep": holds, "nanomsg": fails, "zenoh": fails})[0] == HOLDS
    assert v({"zeromq-reqrep": fails, "nanomsg": fails})[0] == FAILS
    assert v({"zeromq-reqrep": holds, "nanomsg": holds})[0] == FAILS
    assert v({"zeromq-reqrep": holds, "nanomsg": fails, "dds": (TOO_FEW, "")})[0] == TOO_FEW
    assert v({"zeromq-reqrep": ("undecided", ""), "nanomsg": fails})[0] == "undecided"
    assert v({"nanomsg": fails})[0] == "undecided"  # no naive ZeroMQ: nothing to compare


def test_the_share_interval_is_wilsons():
    assert stats.share_ci(0, 0) is None
    p, low, high = stats.share_ci(4, 4)
    assert (p, high) == (1, pytest.approx(1)) and low == pytest.approx(0.510, abs=1e-3)
    p, low, high = stats.share_ci(5, 10)
    assert (low, high) == (pytest.approx(0.237, abs=1e-3), pytest.approx(0.763, abs=1e-3))
