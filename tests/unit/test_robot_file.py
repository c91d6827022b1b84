"""robots/rK.json's type (testbed.files.robotfile): what the run writes reads back the same,
a record without the optional keys reads as empty, and a malformed one is None."""

import json
import os

import pytest

from testbed.files import robotfile
from testbed.files.robotfile import RobotStats

RECORD = {
    "name": "r1", "finish_step": 40, "plans": [[1, "start"]], "crash_step": None,
    "plan_details": [{"step": 1, "cost": float("inf")}], "cpu_s": 1.5, "max_rss_mb": 80,
    "latency_ms": {"answer": {"p50": 2.0}}, "thread_cpu_s": {"main": 1.0, "io": 0.5},
}  # fmt: skip


def test_what_the_run_writes_reads_back_byte_for_byte(tmp_path):
    (tmp_path / "robots").mkdir()
    robotfile.write(tmp_path, 1, RECORD)
    text = (tmp_path / "robots" / "r1.json").read_text()
    assert text == json.dumps(RECORD, indent=1) + "\n"
    rec = robotfile.read(tmp_path, 1)
    assert rec is not None and rec.to_dict() == json.loads(text)
    assert list(rec.to_dict()) == list(RECORD)
    assert (rec.cpu_s, rec.max_rss_mb) == (1.5, 80)
    assert rec.latency_ms["answer"]["p50"] == 2.0 and rec.thread_cpu_s == {"main": 1.0, "io": 0.5}


def test_a_record_without_the_summary_reads_as_empty():
    rec = RobotStats.from_dict({"name": "r1", "cpu_s": None, "latency_ms": None})
    assert rec.cpu_s is None and rec.max_rss_mb is None
    assert rec.latency_ms == {} and rec.thread_cpu_s == {}


@pytest.mark.parametrize(
    "doc",
    [[], {"cpu_s": "1"}, {"max_rss_mb": True}, {"latency_ms": [1]}, {"thread_cpu_s": 3},
     {"thread_cpu_s": {"main": "x"}}],
)  # fmt: skip
def test_a_malformed_record_is_refused(tmp_path, doc):
    with pytest.raises(ValueError):
        RobotStats.from_dict(doc)
    (tmp_path / "robots").mkdir()
    (tmp_path / "robots" / "r1.json").write_text(json.dumps(doc))
    assert robotfile.read(tmp_path, 1) is None


def test_a_missing_cut_or_special_file_is_none(tmp_path):
    assert robotfile.read(tmp_path, 1) is None
    (tmp_path / "robots").mkdir()
    (tmp_path / "robots" / "r1.json").write_text('{"cpu_s": 1')
    assert robotfile.read(tmp_path, 1) is None
    os.mkfifo(tmp_path / "robots" / "r2.json")
    assert robotfile.read(tmp_path, 2) is None
