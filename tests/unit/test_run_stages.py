"""The run's stages without a network: the output directory's claim, the files, the
record's finishing steps, the final status and the last line (testbed.run.files,
testbed.run.record, testbed.run.execute, testbed.run.progress)."""

import csv
import os

import pytest

from common.errors import UsageError
from testbed.files.resultfile import ResultConfig, RunResult
from testbed.run.files import RunFiles, claim_directory, holds_run, make_directory
from testbed.run.progress import summary_line
from testbed.run.record import RobotRecord, RunRecord
from testbed.run.stepclock import ClockSummary
from testbed.run.steploop import final_status


def _old_run(d):
    (d / "robots").mkdir(parents=True)
    (d / "pcaps").mkdir()
    (d / "pcaps" / "r5.pcap").write_bytes(b"old")
    (d / "config.json").write_text("{}")
    (d / "routing.json").write_text("{}")


def test_a_directory_holding_a_run_is_refused_and_left_as_it_was(tmp_path):
    out = tmp_path / "run"
    _old_run(out)
    before = sorted(p.name for p in out.rglob("*"))
    with pytest.raises(UsageError, match="holds a run already.*--replace"):
        claim_directory(str(out), replace=False)
    assert sorted(p.name for p in out.rglob("*")) == before


def test_replace_removes_the_old_run_whole(tmp_path):
    out = tmp_path / "run"
    _old_run(out)
    claim_directory(str(out), replace=True)
    assert holds_run(str(out)), "the claim alone touches nothing"
    make_directory(str(out), capture=False, replace=True)
    assert sorted(os.listdir(out)) == ["display", "robots"]


def test_new_empty_and_foreign_directories_are_fine(tmp_path):
    claim_directory(str(tmp_path / "new" / "deeper"), replace=False)
    (tmp_path / "empty").mkdir()
    claim_directory(str(tmp_path / "empty"), replace=False)
    assert not (tmp_path / "new").exists()


def test_a_directory_under_a_file_is_bad_input(tmp_path):
    (tmp_path / "file").write_text("x")
    with pytest.raises(UsageError, match="not a directory"):
        claim_directory(str(tmp_path / "file" / "run"), replace=False)
    with pytest.raises(UsageError, match="not a directory"):
        claim_directory(str(tmp_path / "file"), replace=False)


def test_run_files_write_their_headers_rows_and_the_clock(tmp_path):
    with RunFiles(str(tmp_path), robots=2) as f:
        f.links(0, {(1, 2), (1, 3)})
        f.coverage(0, 0.1234567)
        f.positions(0, [(1.0, 2.0), (3.0, 4.5)])
        f.frames_out(12.345678)
        f.links(1, {(2, 3)}, {(1, 3)})
    rows = {n: list(csv.reader(open(tmp_path / n))) for n in os.listdir(tmp_path)}
    assert rows["links.csv"] == [["step", "event", "i", "j"], ["0", "add", "1", "2"],
                                 ["0", "add", "1", "3"], ["1", "remove", "1", "3"],
                                 ["1", "add", "2", "3"]]  # fmt: skip
    assert rows["coverage.csv"] == [["step", "coverage"], ["0", "0.12346"]]
    assert rows["positions.csv"] == [["step", "x1", "y1", "x2", "y2"],
                                     ["0", "1.000", "2.000", "3.000", "4.500"]]  # fmt: skip
    assert rows["clock.csv"] == [["step", "t"], ["0", "12.3457"]]


def _record(finish_steps, steps):
    robots = []
    for k, s in enumerate(finish_steps, 1):
        r = RobotRecord(k)
        if s is not None:
            r.finished(s)
            r.finished(s + 50)  # only the first "done" counts
        robots.append(r.outcome())
    clock = ClockSummary(steps, len(robots), 1.0, 1.0, 0, 0)
    return RunRecord("/x", {}, 1.0, "complete", "", None, tuple(robots), clock, {}, {}, None,
                     0.0)  # fmt: skip


def test_a_robots_finish_is_the_step_it_decided_at_and_a_late_done_is_counted():
    on_time, late, claims_ahead = RobotRecord(1), RobotRecord(2), RobotRecord(3)
    on_time.finished(700, 700)
    late.finished(701, 699)  # decided at 699, the world had it two steps later
    late.finished(705, 705)  # only the first "done" counts
    claims_ahead.finished(300, 9999)  # no step it could have decided at: the world's
    assert (on_time.finish_step, on_time.done_late) == (700, 0)
    assert (late.finish_step, late.done_late) == (699, 2)
    assert (claims_ahead.finish_step, claims_ahead.done_late) == (300, 0)
    assert late.outcome().done_late == 2


def test_last_and_mean_finishing_steps_are_told_apart():
    rec = _record([817, 823, 811], steps=824)
    assert rec.last_finish_step == 823 and rec.steps == 824
    assert rec.mean_finish_step == pytest.approx(817.0)
    # A robot that never finished counts the run's last step (as Fig. 2 does).
    rec = _record([100, None], steps=300)
    assert rec.last_finish_step == 100 and rec.mean_finish_step == pytest.approx(200.0)
    assert _record([None], steps=5).last_finish_step is None


def test_a_robot_misses_a_deadline_only_when_alive_and_late():
    r = RobotRecord(1)
    r.answered(4)
    assert not r.missed_deadline(4) and r.missed_deadline(5)
    r.died(6, -9)
    assert not r.missed_deadline(7)
    assert (r.missed, r.missed_steps, r.crash_step, r.exit_status) == (1, [5], 6, -9)


def test_final_status_names_the_first_crash():
    ok = ("complete", "all robots finished by step 9")
    a, b = RobotRecord(1), RobotRecord(2)
    assert final_status(ok, [a, b]) == ok
    b.died(40, -9)
    assert final_status(ok, [a, b]) == ("robot_crashed", "r2 exited with status -9 at step 40")
    a.died(50, 1)
    assert final_status(("robot_crashed", "every robot process died"), [a, b]) == (
        "robot_crashed", "r1 exited with status 1 at step 50; all died",
    )  # fmt: skip


def test_the_last_line_says_where_the_results_are_and_how_to_look():
    result = RunResult(config=ResultConfig(robots=2, comm_range=5.0, laser_range=2.0),
                       status="complete", steps=824, coverage_final=0.99712)  # fmt: skip
    line = summary_line(result, "/tmp/my run")
    assert line == ("testbed run: complete after 824 steps, coverage 99.7%; results in "
                    "/tmp/my run; replay: testbed view '/tmp/my run'")  # fmt: skip
