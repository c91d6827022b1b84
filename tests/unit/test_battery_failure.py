"""--battery-failure: the mid-run kill fixed before the run (testbed.files.failures), added to the
run's kill list, and a sweep grid dimension whose variants share their point's seed."""

import tomllib

import pytest

from common.errors import UsageError
from testbed.files import failures
from testbed.files.runconfig import RunConfig
from testbed.sweep import file as sweepfile
from testbed.sweep.rundir import plan_dict, run_argv
from tests.unit.test_run_options import parse_run

GRID = """
[grid]
robots = [2, 5, 10]
comm_range = [5, 20]
laser_range = [2.0]
middleware = ["nanomsg", "zeromq-reqrep"]
battery_failure = ["none", "midrun"]
runs = 2

[run]
time_scale = { 1 = 30, 2 = 20, 5 = 12, 10 = 6 }
"""


def parse(text: str):
    return sweepfile.parse(tomllib.loads(text), "s.toml")


def test_midrun_is_half_the_rules_typical_steps_and_near_the_measured_middle():
    assert [failures.midrun_step(n, 2.0) for n in (1, 2, 5, 10)] == [1000, 595, 299, 178]
    # media.toml's veth means (5 m, 20 m): the kill falls between 40% and 60% of each.
    measured = {2: (1214, 1127), 5: (579, 529), 10: (393, 377)}
    for n, means in measured.items():
        for m in means:
            assert 0.4 < failures.midrun_step(n, 2.0) / m < 0.6, (n, m)
    # A shorter laser explores longer, so its middle comes later.
    assert failures.midrun_step(10, 1.5) > failures.midrun_step(10, 2.0)


def test_the_failure_kills_the_highest_numbered_robot_after_the_explicit_kills():
    cfg = RunConfig(robots=5, comm_range=5.0, battery_failure="midrun", kill=((2, 40),))
    assert cfg.kills == ((2, 40), (5, 299))
    assert RunConfig(robots=5, comm_range=5.0).kills == ()
    assert RunConfig(robots=5, comm_range=5.0, kill=((1, 9),)).kills == ((1, 9),)


def test_the_flag_parses_refuses_a_lone_robot_and_a_bad_value():
    assert parse_run(["--robots", "3", "--comm-range", "5", "--battery-failure", "midrun"]).kills \
        == ((3, failures.midrun_step(3, 2.0)),)  # fmt: skip
    with pytest.raises(UsageError, match="--battery-failure midrun needs a team of 2 or more"):
        parse_run(["--robots", "1", "--comm-range", "5", "--battery-failure", "midrun"])
    with pytest.raises(UsageError, match="--battery-failure: invalid choice"):
        parse_run(["--robots", "3", "--comm-range", "5", "--battery-failure", "sometimes"])


def test_a_grid_of_failures_names_only_the_failure_and_shares_the_points_seed():
    runs = sweepfile.expand(parse(GRID))
    assert len(runs) == 3 * 2 * 2 * 2 * 2
    ids = {r.run_id: r.config for r in runs}
    plain, failed = ids["n05-c20-l2-zeromqreqrep-k2"], ids["n05-c20-l2-zeromqreqrep-midrun-k2"]
    assert (plain.battery_failure, failed.battery_failure) == ("none", "midrun")
    assert plain.seed == failed.seed == ids["n05-c20-l2-nanomsg-midrun-k2"].seed
    assert plain.seed != ids["n05-c20-l2-zeromqreqrep-k1"].seed  # another run index
    assert failed.time_scale == 12
    assert len({r.point for r in runs}) == len(runs) // 2
    # A newer option: in the plan (and the run's argv) only when not the default.
    assert "battery_failure" not in plan_dict(plain)
    assert plan_dict(failed)["battery_failure"] == "midrun"
    argv = run_argv(["testbed", "run"], plan_dict(failed), "/x")
    assert argv[argv.index("--battery-failure") + 1] == "midrun"
    assert "--kill" not in argv  # the run adds the kill itself, from the option
    assert parse_run(argv[2:-3]) == failed


def test_a_failure_fixed_in_run_is_named_in_every_id_as_not_the_default():
    text = GRID.replace('battery_failure = ["none", "midrun"]\n', "").replace(
        "[run]", '[run]\nbattery_failure = "midrun"'
    )
    runs = sweepfile.expand(parse(text))
    assert {r.config.battery_failure for r in runs} == {"midrun"}
    assert runs[0].run_id == "n02-c5-l2-nanomsg-midrun-k1"


@pytest.mark.parametrize(
    ("text", "key"),
    [
        (GRID.replace("robots = [2, 5, 10]", "robots = [1, 2]"), "grid.battery_failure"),
        (GRID.replace('battery_failure = ["none", "midrun"]\n', "").replace(
            "[run]", '[run]\nbattery_failure = "midrun"').replace(
            "robots = [2, 5, 10]", "robots = [1]"), "run.battery_failure"),
        (GRID.replace('"midrun"]', '"always"]'), "grid.battery_failure"),
    ],
)  # fmt: skip
def test_bad_failures_in_a_sweep_file_are_one_line_naming_the_key(text, key):
    with pytest.raises(UsageError, match=f"s.toml: {key}: ") as e:
        parse(text)
    assert "\n" not in str(e.value)


def test_a_lone_robot_without_failure_is_still_a_sweep():
    runs = sweepfile.expand(
        parse(
            GRID.replace("robots = [2, 5, 10]", "robots = [1, 2]").replace(
                'battery_failure = ["none", "midrun"]\n', ""
            )
        )
    )
    assert {r.config.robots for r in runs} == {1, 2}
