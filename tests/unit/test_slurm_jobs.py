"""The Slurm jobs file's type (testbed.files.slurmjobs): what submit writes reads back the
same, byte for byte, no file is no jobs, and a malformed file is one line naming the key."""

import json

import pytest

from common.errors import UsageError
from testbed.files import slurmjobs
from testbed.files.slurmjobs import SlurmJob, SlurmJobs

WRITTEN = {
    "jobs": [
        {"job": 41, "list": "/s/out/slurm/tasks-1.txt", "robots": 1, "cpus": 2, "minutes": 30,
         "runs": ["n01-c5-l2-r0", "n01-c10-l2-r0"]},
        {"job": 42, "list": "/s/out/slurm/tasks-2.txt", "robots": 4, "cpus": 3, "minutes": 51,
         "runs": ["n04-c5-l2-r0"]},
    ]
}  # fmt: skip


def test_what_submit_writes_reads_back_byte_for_byte(tmp_path):
    jobs = SlurmJobs.from_json(json.loads(json.dumps(WRITTEN)))
    assert jobs.to_json() == WRITTEN
    assert [list(j.to_dict()) for j in jobs.jobs] == [list(d) for d in WRITTEN["jobs"]]
    (tmp_path / "slurm").mkdir()
    slurmjobs.write(tmp_path, jobs)
    text = (tmp_path / "slurm" / "jobs.json").read_text()
    assert text == json.dumps(WRITTEN, indent=1) + "\n"  # what the writer wrote before the type
    assert slurmjobs.read(tmp_path) == jobs


def test_the_fields_readers_use():
    (first, second) = SlurmJobs.from_json(WRITTEN).jobs
    assert first == SlurmJob(job=41, task_list="/s/out/slurm/tasks-1.txt", robots=1, cpus=2,
                             minutes=30, runs=("n01-c5-l2-r0", "n01-c10-l2-r0"))  # fmt: skip
    assert (second.job, second.runs) == (42, ("n04-c5-l2-r0",))


def test_no_file_is_no_jobs(tmp_path):
    assert slurmjobs.read(tmp_path) == SlurmJobs()
    assert SlurmJobs.from_json({}).jobs == ()


def _entry(**change):
    return {"jobs": [dict(WRITTEN["jobs"][0], **change)]}


@pytest.mark.parametrize(
    ("doc", "key"),
    [
        ([], "not a JSON object"),
        ({"jobs": {}}, "jobs is not a list"),
        ({"jobs": [1]}, "jobs[0] is not an object"),
        (_entry(job="41"), "jobs[0].job"),
        (_entry(job=0), "jobs[0].job"),
        (_entry(robots=True), "jobs[0].robots"),
        (_entry(cpus=1.5), "jobs[0].cpus"),
        (_entry(minutes=None), "jobs[0].minutes"),
        (_entry(list=3), "jobs[0].list"),
        (_entry(runs="n01"), "jobs[0].runs"),
        (_entry(runs=["../x"]), "jobs[0].runs[0]"),
        (_entry(runs=["a\nb"]), "jobs[0].runs[0]"),
    ],
)
def test_a_malformed_file_is_one_line_naming_the_key(tmp_path, doc, key):
    with pytest.raises(ValueError) as e:
        SlurmJobs.from_json(doc)
    assert key in str(e.value)
    (tmp_path / "slurm").mkdir()
    (tmp_path / "slurm" / "jobs.json").write_text(json.dumps(doc))
    with pytest.raises(UsageError) as u:
        slurmjobs.read(tmp_path)
    said = str(u.value)
    assert "jobs.json" in said and key in said and "\n" not in said


def test_a_file_that_is_not_json_is_one_line(tmp_path):
    (tmp_path / "slurm").mkdir()
    (tmp_path / "slurm" / "jobs.json").write_text('{"jobs": [')
    with pytest.raises(UsageError, match="jobs.json: unreadable: not valid JSON"):
        slurmjobs.read(tmp_path)
