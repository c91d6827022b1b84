"""The in-process twin of a lone robot's run (testbed.run.twin) is exact: it writes, byte for
byte, the positions.csv the runs at time scale 5 wrote (tests/data/lone-k5, seeds 1-3: 1901,
1989 and 1964 steps; tests/integration/test_lone_exactness.py holds both robot programs to
the same files), and its comparison finds where a run's path left it."""

import csv
import io
import json
import os
import time

import pytest

from testbed.files.isolation import Outage
from testbed.files.runconfig import RunConfig
from testbed.run import fidelity, twin

DATA = os.path.join(os.path.dirname(__file__), "..", "data", "lone-k5")
STEPS = {1: 1901, 2: 1989, 3: 1964}


def _expected(seed: int) -> str:
    with open(os.path.join(DATA, f"seed{seed}.positions.csv"), newline="") as f:
        return f.read()


def _cfg(seed: int, **kw) -> RunConfig:
    args: dict = dict(robots=1, comm_range=20.0, laser_range=2.0, seed=seed, time_scale=5.0)
    return RunConfig(**{**args, **kw})


@pytest.mark.parametrize("seed", sorted(STEPS))
def test_the_twin_takes_the_runs_steps_and_path(seed):
    t0 = time.perf_counter()
    t = twin.twin(_cfg(seed))
    assert time.perf_counter() - t0 < 5.0  # well under a second with the step core
    assert (t.status, t.steps, t.finish_step) == ("complete", STEPS[seed], STEPS[seed] - 1)
    assert t.csv_text() == _expected(seed)


def test_the_time_scale_and_the_network_change_nothing():
    a = twin.twin(_cfg(1))
    b = twin.twin(_cfg(1, time_scale=100.0, routing="babel", loss_pct=10.0))
    assert a.rows == b.rows


def test_the_step_cap_ends_the_twin():
    t = twin.twin(_cfg(2, max_steps=300))
    assert (t.status, t.steps, t.finish_step) == ("step_cap", 300, None)
    assert t.csv_text() == "".join(_expected(2).splitlines(keepends=True)[:302])


def _rows(text: str) -> list[list[str]]:
    return list(csv.reader(io.StringIO(text)))


def test_differences():
    t = twin.twin(_cfg(3, max_steps=50))
    rows = _rows(t.csv_text())
    assert twin.differences(rows, t.rows) == (None, 0)
    moved = [r[:] for r in rows]
    moved[31][1] = moved[33][2] = "9.999"  # steps 30 and 32
    assert twin.differences(moved, t.rows) == (30, 2)
    assert twin.differences(rows[:20], t.rows) == (19, 32)  # ended before its twin: 19-50
    # A late "done": the world ran on while the robot stood where its twin ended.
    still = [*rows, [str(len(rows) - 1), *rows[-1][1:]], [str(len(rows)), *rows[-1][1:]]]
    assert twin.differences(still, t.rows) == (None, 0)
    went_on = [*still, [str(len(rows) + 1), "1.000", "1.000"]]
    assert twin.differences(went_on, t.rows) == (len(rows) + 1, 1)
    assert twin.differences([["step", "x2", "y2"], *rows[1:]], t.rows) == (0, 1)
    assert twin.differences([], t.rows) == (0, 52)


def test_what_the_twin_does_not_cover():
    assert "team of 2" in str(twin.not_covered(_cfg(1, robots=2)))
    assert twin.not_covered(_cfg(1, kill=((1, 50),))) == "--kill stops the robot"
    assert "isolate" in str(twin.not_covered(_cfg(1, isolate=(Outage(1, 10, 10),))))
    assert "robot_crashed" in str(twin.not_covered(_cfg(1), "robot_crashed"))
    assert twin.not_covered(_cfg(1), "step_cap") is None
    with pytest.raises(ValueError, match="no twin"):
        twin.twin(_cfg(1, robots=2))


def _run_dir(tmp_path, seed: int, positions: str, **kw) -> tuple[str, dict]:
    cfg = _cfg(seed, **kw)
    config = cfg.to_dict()
    config.update(name="t", display=2)  # preparing adds these (and starts, timer_phases)
    (tmp_path / "config.json").write_text(json.dumps(config))
    (tmp_path / "positions.csv").write_text(positions, newline="")
    return str(tmp_path), config


def test_check_a_run(tmp_path):
    out, config = _run_dir(tmp_path, 2, _expected(2))
    got = twin.check(out, config, "complete")
    assert isinstance(got, dict)
    assert got["ok"] is True and got["steps"] == STEPS[2] and "differs_from_step" not in got
    rows = _rows(_expected(2))
    rows[101][2] = "0.000"  # step 100
    buf = io.StringIO(newline="")
    csv.writer(buf).writerows(rows)
    (tmp_path / "positions.csv").write_text(buf.getvalue(), newline="")
    got = twin.check(out, config, "complete")
    assert isinstance(got, dict)
    assert got["ok"] is False and got["differs_from_step"] == 100 and got["steps_differing"] == 1
    assert twin.check(out, config, "interrupted") == (
        "not applicable: the run ended interrupted, not by itself"
    )


def test_check_uses_the_runs_own_starts_and_phases(tmp_path):
    out, config = _run_dir(tmp_path, 1, _expected(1))
    config.update(starts=[[1.0, 1.0]], timer_phases=[3])  # not what seed 1 gives
    got = twin.check(out, config, "complete")
    assert isinstance(got, dict) and got["ok"] is False and got["differs_from_step"] == 0


def _verdict(**kw) -> dict:
    return fidelity.verdict(fidelity.measures(0.0, [{}], **kw))


def test_a_path_off_its_twin_is_not_faithful_whatever_else():
    t = {"ok": False, "steps": 1901, "differs_from_step": 57, "steps_differing": 20}
    v = fidelity.with_twin(_verdict(), t)
    assert v["ok"] is False
    assert v["reason"] == "the path differs from its in-process twin from step 57 (20 steps differ)"
    assert v["twin"]["differs_from_step"] == 57 and "measures" in v
    late = fidelity.verdict(fidelity.measures(0.05, [{}]))  # late steps already: both said
    v = fidelity.with_twin(late, {"ok": False, "steps": 1901, "differs_from_step": 3})
    assert v["reason"].startswith("5.0% of step deadlines missed") and "from step 3" in v["reason"]


def test_a_path_equal_to_its_twin_or_no_twin_leaves_the_verdict():
    for t in ({"ok": True, "steps": 1901, "wall_s": 0.4}, "not applicable: a team of 3: ..."):
        v = fidelity.with_twin(_verdict(), t)
        assert v["ok"] is True and "reason" not in v and v["twin"] == t
    late = fidelity.verdict(fidelity.measures(0.05, [{}]))
    v = fidelity.with_twin(late, {"ok": True, "steps": 1901, "wall_s": 0.4})
    assert v["ok"] is False and v["reason"] == late["reason"]
    assert list(v)[:2] == ["ok", "reason"]


def test_main_checks_run_directories(tmp_path, capsys):
    assert twin.main([str(tmp_path / "none")]) == 0
    assert "not applicable: no readable result.json" in capsys.readouterr().out
