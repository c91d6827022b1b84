"""The neighbours benchmark's pure parts, without a network: each AODV daemon's lateness is
judged apart, within the steps as the fidelity verdict judges it; the worst of each kind of
process over several runs; bad TESTBED_NEIGHBOURS_* is one line and exit 2."""

import json

import pytest

from testbed.bench import neighbours as nb


def _timer(worst):
    ms = [w[2] for w in worst]
    return {"n": len(worst), "late": len(worst), "max": max(ms, default=0.0), "hist": {},
            "worst": worst}  # fmt: skip


def _run_dir(tmp_path, robot_hello, display_hello, display_expiry=()):
    (tmp_path / "aodv").mkdir()
    (tmp_path / "clock.csv").write_text("step,t\n0,100.0\n1,100.02\n500,110.0\n")
    for k, hello, expiry in ((1, robot_hello, []), (2, display_hello, list(display_expiry))):
        doc = {"messages_sent": {"HELLO": 3},
               "timer_lateness_ms": {"hello": _timer(hello), "expiry": _timer(expiry)}}  # fmt: skip
        (tmp_path / "aodv" / f"r{k}.json").write_text(json.dumps(doc))
    return str(tmp_path)


def test_each_daemon_apart_and_only_while_the_robots_stepped(tmp_path):
    out = _run_dir(
        tmp_path,
        robot_hello=[[99.0, 99.9, 4000.0], [105.0, 105.05, 250.0]],  # the first before step 0
        display_hello=[[109.0, 109.1, 500.0], [111.0, 111.2, 900.0]],  # the second after the end
        display_expiry=[[103.0, 103.01, 50.0]],
    )
    assert nb.stepping(out) == (100.0, 110.0)
    got = nb.daemon_lateness(out)
    assert got["robot_daemon"] == {"hello_ms": 250.0, "expiry_ms": 0.0}
    assert got["display_daemon"] == {"hello_ms": 500.0, "expiry_ms": 50.0}


def test_a_daemon_without_statistics_is_none(tmp_path):
    out = _run_dir(tmp_path, [], [])
    (tmp_path / "aodv" / "r2.json").unlink()
    assert nb.daemon_lateness(out)["display_daemon"] is None
    assert nb.daemon_lateness(out)["robot_daemon"] == {"hello_ms": 0.0, "expiry_ms": 0.0}


def _summary(world_ms, plan, hello_robot, hello_display, frame):
    return {
        "world": {"worst_ms_late": world_ms},
        "robot_process": {
            "plan_age_max_steps": plan,
            "timer_late_max_steps": 0.0,
            "frame_answer_max_ms": 12.0,
        },  # fmt: skip
        "aodv": {
            "robot_daemon": {"hello_ms": hello_robot, "expiry_ms": 0.0},
            "display_daemon": None
            if hello_display is None
            else {"hello_ms": hello_display, "expiry_ms": 3.0},
        },  # fmt: skip
        "display": {"frame_max_ms": frame},
    }


def test_worst_of_each_kind_over_runs():
    w = nb.worst([_summary(3.0, 0.0, 40.0, None, None), _summary(1.0, 1.0, 20.0, 600.0, 30.0)])
    assert w == {
        "world_step_ms": 3.0,
        "robot_plan_age_steps": 1.0,
        "robot_timer_late_steps": 0.0,
        "robot_frame_answer_ms": 12.0,
        "robot_daemon_hello_ms": 40.0,
        "robot_daemon_expiry_ms": 0.0,
        "display_daemon_hello_ms": 600.0,
        "display_daemon_expiry_ms": 3.0,
        "display_frame_ms": 30.0,
    }


@pytest.mark.parametrize(
    "var, value",
    [("TESTBED_NEIGHBOURS_KINDS", "disk,floods"), ("TESTBED_NEIGHBOURS_KINDS", ","),
     ("TESTBED_NEIGHBOURS_SEEDS", "2,7"), ("TESTBED_NEIGHBOURS_NAME", "../x"),
     ("TESTBED_NEIGHBOURS_DAEMON", "cpp,python"), ("TESTBED_NEIGHBOURS_DAEMON", "rust")],
)  # fmt: skip
def test_bad_environment_exits_2(monkeypatch, capsys, var, value):
    monkeypatch.setenv(var, value)
    monkeypatch.setattr(nb, "measure", lambda *a: pytest.fail("measured"))
    with pytest.raises(SystemExit) as e:
        nb.run()
    assert e.value.code == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"bench neighbours: {var}=") and "\n" not in err


def test_environment_chooses_kinds_seeds_and_daemon(monkeypatch):
    monkeypatch.setenv("TESTBED_NEIGHBOURS_KINDS", "busy, disk")
    monkeypatch.setenv("TESTBED_NEIGHBOURS_SEEDS", "3")
    monkeypatch.setenv("TESTBED_NEIGHBOURS_DAEMON", "python")
    asked = []

    def measure(kinds, seeds, daemon):
        asked.append((kinds, seeds, daemon))
        return {"neighbours": {}}

    monkeypatch.setattr(nb, "measure", measure)
    monkeypatch.setattr(nb, "write", lambda name, data: name)
    nb.run()
    assert asked == [(("busy", "disk"), (3,), "python")]
