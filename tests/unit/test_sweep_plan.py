"""The sweep's planner (what is done, to do, partial, skipped), command line and progress."""

import io
import json

import pytest

from testbed.sweep import file as sweepfile
from testbed.sweep import plan as sweepplan
from testbed.sweep import progress as sweepprogress
from testbed.sweep import rundir
from testbed.sweep import runner as sweeprunner
from tests.unit.test_sweep_synthetic import write_run


def spec(**kw):
    base = dict(robots=(1, 2), comm_range=(5.0,), laser_range=(2.0,), runs=2)
    base.update(kw)
    return sweepfile.SweepSpec.of(**base)


def test_plan_sorts_runs_by_what_is_on_disk(tmp_path):
    runs = sweepfile.expand(spec())
    done, partial = runs[0], runs[1]
    write_run(tmp_path, done)
    pdir = tmp_path / "runs" / partial.run_id
    pdir.mkdir(parents=True)
    (pdir / "config.json").write_text("{}")
    (pdir / "result.json.tmp").write_text("{")  # a run killed while writing its result
    p = sweepplan.plan(runs, tmp_path, netem=False)
    assert [r.run_id for r in p.done] == [done.run_id]
    assert [r.run_id for r in p.todo] == [r.run_id for r in runs[1:]]
    assert [r.run_id for r in p.partial] == [partial.run_id]
    assert p.skipped == {}


def test_delay_points_are_skipped_without_netem_with_a_reason(tmp_path):
    runs = sweepfile.expand(spec(delay_ms=(0.0, 50.0), runs=1))
    p = sweepplan.plan(runs, tmp_path, netem=False)
    assert sorted(p.skipped) == ["n01-c5-l2-d50-k1", "n02-c5-l2-d50-k1"]
    assert all("sch_netem" in why for why in p.skipped.values())
    assert len(p.todo) == 2
    assert not sweepplan.plan(runs, tmp_path, netem=True).skipped


def test_a_finished_delay_run_stays_done_without_netem(tmp_path):
    runs = sweepfile.expand(spec(delay_ms=(50.0,), runs=1))
    write_run(tmp_path, runs[0])
    p = sweepplan.plan(runs, tmp_path, netem=False)
    assert [r.run_id for r in p.done] == [runs[0].run_id]


def test_config_mismatch_is_found(tmp_path):
    runs = sweepfile.expand(spec())
    write_run(tmp_path, runs[0])
    assert sweepplan.config_mismatch(tmp_path, runs[0]) is None
    changed = sweepfile.expand(spec(max_steps=123))[0]
    assert "max_steps" in sweepplan.config_mismatch(tmp_path, changed)
    # How fast is not what: a run the sweep made slower still answers its point.
    assert sweepplan.config_mismatch(tmp_path, sweepfile.expand(spec(time_scale=3.0))[0]) is None


def test_run_argv():
    cfg = sweepfile.expand(spec(capture=True, time_scale=2.5))[0].config
    argv = rundir.run_argv(["testbed", "run"], cfg, "/x/runs/a")
    assert argv[:2] == ["testbed", "run"]
    assert argv[-3:] == ["--quiet", "--out", "/x/runs/a"]
    assert "--capture" in argv and "--map" not in argv
    i = argv.index("--robots")
    assert argv[i + 1] == "1"
    assert float(argv[argv.index("--comm-range") + 1]) == 5
    assert argv[argv.index("--time-scale") + 1] == "2.5"
    assert argv[argv.index("--seed") + 1] == str(cfg.seed)
    assert float(argv[argv.index("--loss") + 1]) == 0


def test_default_jobs():
    assert sweepplan.default_jobs(1) == 1
    assert sweepplan.default_jobs(2) == 1
    assert sweepplan.default_jobs(8) == 4


def test_progress_line_per_run_when_not_a_tty():
    out = io.StringIO()
    p = sweepprogress.Progress(4, out)
    runs = sweepfile.expand(spec())
    assert p.eta(runs, 0, 1) is None
    p.record(1, 10.0)
    p.record(2, 30.0)
    # two remaining runs (1 and 2 robots) cost 10 + 30 s, at 2 jobs: 20 s
    assert p.eta(runs[2:], 0, 2) == pytest.approx(20.0)
    p.update(2, 0, 0, 20.0, "n01-c5-l2-k1: complete in 10 s")
    p.update(2, 1, 0, 20.0)  # no event: nothing printed off a TTY
    text = out.getvalue()
    assert text.count("\n") == 1 and "\r" not in text
    assert "2/4 done" in text and "ETA 0m20s" in text


def test_progress_redraws_in_place_on_a_tty():
    class Tty(io.StringIO):
        def isatty(self):
            return True

    out = Tty()
    p = sweepprogress.Progress(3, out)
    p.update(0, 1, 0, None)
    p.update(1, 1, 0, 5.0, "n01: complete")
    p.close()
    text = out.getvalue()
    assert text.startswith("\r[") and "ETA ?" in text and "1/3 done" in text
    assert text.endswith("\n")


def test_sweep_json_is_written_atomically(tmp_path):
    s = spec()
    runs = sweepfile.expand(s)
    (tmp_path / "runs").mkdir()
    quiet = io.StringIO()
    sw = sweeprunner.Sweep(s, runs, tmp_path, 1, False, command=["true"], progress_stream=quiet)
    sw._write_state()
    doc = json.loads((tmp_path / "sweep.json").read_text())
    assert [r["id"] for r in doc["runs"]] == [r.run_id for r in runs]
    assert all(r["status"] == "pending" for r in doc["runs"])
    assert not (tmp_path / "sweep.json.tmp").exists()


def test_an_interrupted_run_is_not_done(tmp_path):
    """A run stopped by Ctrl-C writes its result.json (nothing lost) but is redone."""
    runs = sweepfile.expand(spec())
    write_run(tmp_path, runs[0])
    doc = json.loads((rundir.run_dir(tmp_path, runs[0].run_id) / "result.json").read_text())
    doc["status"] = "interrupted"
    write_run(tmp_path, runs[1], doc=doc)
    p = sweepplan.plan(runs, tmp_path, netem=False)
    assert runs[0] in p.done and runs[1] in p.todo and runs[1] in p.partial
