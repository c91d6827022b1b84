"""testbed.analysis.scalecompare: two sweeps of the same points, within the noise or not."""

import dataclasses

from testbed.analysis import scalecompare as sc
from testbed.analysis.runs import load_run
from testbed.files import routingfile
from testbed.sweep import file as sweepfile
from tests.unit.test_sweep_synthetic import result_doc, write_run


def _row(steps, comm=20, robots=10, pdf=0.99, scale=1.0, requests=2.0, tcp=True):
    return sc.ScaleRun(
        routing="aodv", laser_range=2.0, comm_range=comm, robots=robots, time_scale=scale,
        tcp_emulated=tcp, steps=steps, requests=requests, pdf=pdf, delay_ms=0.3,
        delay_mean_ms=None, retrans_per_flow=None, control_pkts_per_robot_s=1.0,
        control_bytes_per_robot_s=70.0,
    )  # fmt: skip


def test_overlapping_intervals_agree_and_separated_ones_do_not():
    a = sc.points([_row(s) for s in (360, 370, 380)] + [_row(s, comm=5) for s in (400, 410, 420)])
    b = sc.points(
        [_row(s, scale=8) for s in (365, 375, 385)]
        + [_row(s, comm=5, scale=8) for s in (500, 505, 510)]
    )
    line = sc.sentence("steps", "exploration steps", ".0f", a, b, ("rt", "dil"))
    assert "within the noise at 1 of 2 points" in line
    assert "aodv, laser 2 m, range 5 m, 10 robots: dil 505 above rt's 410" in line


def test_one_run_on_a_side_is_not_judged():
    a = sc.points([_row(360)])
    b = sc.points([_row(s) for s in (360, 380)])
    line = sc.sentence("steps", "exploration steps", ".0f", a, b, ("a", "b"))
    assert "not judged" in line and "within" not in line


def test_the_section_lists_both_sweeps_per_point_with_their_scales_and_what_was_left_out():
    a = [_row(s) for s in (360, 370, 380)]
    b = [_row(s, scale=8) for s in (365, 375)]
    text = "\n".join(sc.section(a, b, ("rt", "dil"), (0, 2)))
    assert "| aodv, laser 2 m, range 20 m, 10 robots | rt | 3 | 1 | 370 [" in text
    assert "| aodv, laser 2 m, range 20 m, 10 robots | dil | 2 | 8 | 370 [" in text
    assert "0 in rt, 2 in dil" in text
    assert text.count("\n- ") == len(sc.MEASURES)


def test_tcps_measures_across_scales_are_compared_only_where_tcp_kept_emulated_time():
    def rows(pdfs, scale, tcp):
        return [_row(360, pdf=p, scale=scale, tcp=tcp) for p in pdfs]

    real = sc.points(rows((0.67, 0.68, 0.69), 1.0, True))
    undilated = sc.points(rows((0.77, 0.78, 0.79), 6.0, False))
    dilated = sc.points(rows((0.77, 0.78, 0.79), 6.0, True))
    line = sc.sentence("pdf", "packet delivery fraction", ".3f", real, undilated, ("rt", "dil"))
    assert line == (
        "- Packet delivery fraction: not compared at 1 point, where the time scales differ "
        "and TCP's timers were not dilated (result.json's fidelity.network)."
    )
    # With TCP dilated the same numbers are compared, and differ beyond the noise.
    line = sc.sentence("pdf", "packet delivery fraction", ".3f", real, dilated, ("rt", "dil"))
    assert "within the noise at 0 of 1 points; beyond it at" in line
    # The robots' own measures are compared whatever TCP did.
    line = sc.sentence("steps", "exploration steps", ".0f", real, undilated, ("rt", "dil"))
    assert "within the noise at 1 of 1 points" in line
    # At one time scale TCP's measures are comparable, dilated or not.
    same = sc.points(rows((0.76, 0.77, 0.78), 6.0, False))
    line = sc.sentence("pdf", "PDF", ".3f", same, undilated, ("a", "b"))
    assert "within the noise at 1 of 1" in line
    a, b = rows((0.67, 0.68, 0.69), 1.0, True), rows((0.77, 0.78, 0.79), 6.0, False)
    text = "\n".join(sc.section(a, b, ("rt", "dil"), (0, 0)))
    assert "| dil | 3 | 6 (TCP undilated) |" in text


def test_a_runs_mean_delay_is_emulated_and_its_retransmissions_are_counted_per_flow(tmp_path):
    spec = sweepfile.SweepSpec.of(robots=(2,), comm_range=(5.0,), laser_range=(2.0,), runs=1)
    planned = sweepfile.expand(spec)[0]
    c = dataclasses.replace(planned.config, time_scale=6.0)
    run = load_run(write_run(tmp_path, planned, result_doc(c, [90, 100], 100)))
    metrics = {"pdf": 0.9, "delay_ms_median": 0.01, "delay_ms_mean": 0.5, "tcp_flows": 4,
               "tcp_transmissions": 130, "tcp_segments_sent": 100}  # fmt: skip
    row = sc.run_row(run, routingfile.parse(metrics))
    assert row.delay_mean_ms == 0.5 * 6  # wall ms x the time scale
    assert row.retrans_per_flow == 30 / 4
    assert sc.run_row(run, None).retrans_per_flow is None
