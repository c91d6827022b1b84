"""The protocols section of the report: each protocol beside the oracle, and the verdict on
the paper's choice of AODV, on a synthetic protocols sweep with known numbers."""

from dataclasses import replace

from testbed.analysis import figures, protocols, report
from testbed.files import routingfile
from testbed.sweep import file as sweepfile
from tests.unit.test_sweep_synthetic import result_doc, write_run

# Steps and control packets per (routing): AODV as fast as babel, quieter; batman slower.
STEPS = {"aodv": 400, "babel": 400, "batman": 700, "oracle": 380}
CONTROL = {"aodv": 20, "babel": 90, "batman": 60, "oracle": 0}


def sweep(tmp_path):
    spec = sweepfile.SweepSpec.of(
        robots=(5,), comm_range=(10.0,), laser_range=(2.0,), runs=3,
        routing=("aodv", "babel", "batman", "oracle"),
    )  # fmt: skip
    metrics = {}
    for run in sweepfile.expand(spec):
        c = run.config
        steps = STEPS[c.routing] + 5 * run.index
        write_run(tmp_path, run, result_doc(c, [steps] * 5, steps + 1))
        robot_s = 6 * 10.0 * c.time_scale  # 5 robots and the display, 10 s of wall time
        metrics[run.run_id] = {
            "duration_s": 10.0, "control_tx_packets": CONTROL[c.routing] * robot_s,
            "control_tx_bytes": 1000.0, "pdf": 0.9 if c.routing != "oracle" else 1.0,
            "delay_ms_median": 2.0,
        }  # fmt: skip
    return lambda run: routingfile.parse(m) if (m := metrics.get(run.run_id)) else None


def test_protocol_rows_per_point_with_steps_intervals(tmp_path):
    made = figures.make_all(tmp_path, metrics_of=sweep(tmp_path))
    rows = {r.routing: r for r in made.tables.protocols}
    assert list(rows) == ["aodv", "babel", "batman", "oracle"]
    assert rows["aodv"].measures.steps == 410 and rows["aodv"].n == 3
    assert rows["aodv"].steps_ci_low < 410 < rows["aodv"].steps_ci_high
    assert abs(rows["babel"].measures.control_pkts_per_robot_s - 90) < 1e-9
    assert rows["oracle"].measures.control_pkts_per_robot_s == 0
    # The paper's figures are drawn for AODV alone, not pooled over protocols.
    assert [r.steps_per_run for r in made.tables.fig2] == [(405, 410, 415)]


def test_choice_holds_against_babel_but_batman_rule_is_applied_too(tmp_path):
    made = figures.make_all(tmp_path, metrics_of=sweep(tmp_path))
    rows = made.tables.protocols
    by = {r.routing: r for r in rows}
    assert protocols.choice_holds(by) == (True, "fewer control packets, steps within noise")
    quieter_babel = replace(
        by["babel"], measures=replace(by["babel"].measures, control_pkts_per_robot_s=5.0)
    )
    ok, why = protocols.choice_holds({**by, "babel": quieter_babel})
    assert not ok and "babel sends fewer control packets" in why
    faster_batman = replace(by["batman"], measures=replace(by["batman"].measures, steps=300),
                            steps_ci_low=290, steps_ci_high=310)  # fmt: skip
    ok, why = protocols.choice_holds({**by, "batman": faster_batman})
    assert not ok and "batman needs fewer steps beyond noise" in why
    text = "\n".join(protocols.section(rows))
    assert "At 1 of 1 points (all)." in text and "(1.05x)" in text  # 410 / 390


def test_bytes_and_delivery_are_counted_beside_the_rule(tmp_path):
    made = figures.make_all(tmp_path, metrics_of=sweep(tmp_path))
    by = {r.routing: r for r in made.tables.protocols}
    # Every protocol's captures carry 1000 bytes and PDF 0.9: AODV beats none on either.
    assert protocols.beside_the_rule([by]) == [
        "- AODV sends fewer control bytes per robot per second than each proactive protocol "
        "at 0 of 1 points.",
        "- AODV delivers a larger share of the robots' TCP packets than each proactive "
        "protocol at 0 of 1 points.",
    ]
    a = by["aodv"]
    better = replace(a, measures=replace(a.measures, control_bytes_per_robot_s=0.001, pdf=0.95))
    worse_than_batman = {**by, "aodv": replace(better, measures=replace(better.measures, pdf=0.5))}
    lines = protocols.beside_the_rule([{**by, "aodv": better}, worse_than_batman, {"aodv": better}])
    assert "at 2 of 2 points" in lines[0] and "at 1 of 2 points" in lines[1]
    text = "\n".join(protocols.section(made.tables.protocols))
    assert "Beside the rule (other measures, not part of the verdict):" in text


def test_report_has_the_section_only_for_a_protocols_sweep(tmp_path):
    path, _ = report.write_report(tmp_path, metrics_of=sweep(tmp_path))
    assert "## Routing protocols against the oracle" in path.read_text()
    single = tmp_path / "single"
    for run in sweepfile.expand(sweepfile.SweepSpec.of(robots=(2,), comm_range=(5.0,),
                                                    laser_range=(2.0,))):  # fmt: skip
        write_run(single, run)
    path, _ = report.write_report(single, metrics_of=lambda run: None)
    assert "Routing protocols" not in path.read_text()
