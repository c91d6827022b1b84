"""The run options (testbed.files.runconfig, testbed.files.options): one table, and the
command line, the sweep file checks and the argv a sweep hands a run all made from it, as a
closed loop."""

import dataclasses
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from common.errors import UsageError
from node.native import unbuilt_reason
from testbed import cli
from testbed.files.isolation import Outage
from testbed.files.runconfig import NET_OPTIONS, OPTIONS, RunConfig, to_argv
from testbed.run.arguments import config_from_args
from testbed.sweep import file as sweepfile
from testbed.sweep.rundir import plan_dict, run_argv
from topology.spec import ROUTINGS

REPO = Path(__file__).resolve().parents[2]
# Where it goes, how it shows, when it steps (a sweep's steps-over file and start gate).
RUN_ONLY = {"out", "name", "quiet", "replace", "steps_over", "start_when", "start_timeout"}


def parse_run(argv: list[str]) -> RunConfig:
    args = cli.build_parser(["run"]).parse_args(["run", *argv, "--out", "/x"])
    return config_from_args(args)


def run_parser():
    sub = next(a for a in cli.build_parser(["run"])._actions if a.dest == "cmd")
    return sub.choices["run"]


def net_up_parser():
    sub = next(a for a in cli.build_parser(["net"])._actions if a.dest == "cmd")
    net_sub = next(a for a in sub.choices["net"]._actions if a.dest == "net_cmd")
    return net_sub.choices["up"]


def test_every_option_round_trips_through_argv_with_non_default_values():
    cfg = RunConfig(
        robots=7, comm_range=12.5, laser_range=1.5, seed=42, time_scale=0.1 + 0.2,
        routing="oracle", aodv_profile="ns3", map="maps/office.png", loss_pct=12.5,
        delay_ms=40.0, range_model="los", wall_loss_pct=30.0, capture=True, max_steps=1234,
        coordination="paper", start="spread", map_cell=0.1, laser_rays=180, speed=0.05,
        map_period=7, flood="blind", display_pos=(3.5, 4.25), snapshots=(200, 600),
        kill=((2, 150), (3, 300)), view="127.0.0.1:8123", medium="ns3-wifi",
        wifi_loss="logdistance", wifi_standard="80211b", wifi_rate="DsssRate1Mbps",
        middleware="zeromq-reqrep", battery_failure="midrun", robot="python",
        aodv_daemon="python",
    )  # fmt: skip
    # --isolate is for the veth medium: its non-default value rides on a veth config.
    veth = dataclasses.replace(
        cfg, medium="veth", wifi_loss="range", wifi_standard="80211a", wifi_rate="",
        isolate=(Outage(3, 200, 100), Outage(5, 10, 1), Outage(3, 250, 20)),
        middleware="dds", maps="pubsub",
    )  # fmt: skip
    for opt in OPTIONS:  # every option non-default in one of the two
        assert opt.default != getattr(cfg, opt.name) or opt.default != getattr(veth, opt.name)
    assert parse_run(to_argv(cfg)) == cfg
    assert parse_run(to_argv(veth)) == veth
    assert RunConfig.from_dict(veth.to_dict()) == veth


def test_defaults_agree_and_the_table_is_the_parser():
    assert parse_run(["--robots", "2", "--comm-range", "5"]) == RunConfig(robots=2, comm_range=5)
    dests = {a.dest for a in run_parser()._actions if a.dest != "help"}
    assert dests == {opt.name for opt in OPTIONS} | RUN_ONLY
    fields = {f.name for f in dataclasses.fields(RunConfig)}
    assert {opt.name for opt in OPTIONS} <= fields
    assert fields - {opt.name for opt in OPTIONS} == {"radius", "plan_period"}  # no flags


def test_help_gives_every_options_default_and_unit():
    text = " ".join(run_parser().format_help().split())
    for opt in OPTIONS:
        line = " ".join(opt.help_text().replace("%%", "%").split())
        assert line in text, opt.name
        assert ("required" if opt.required else "default") in line, opt.name
        assert opt.unit in line
    for flag in ("--seed", "--time-scale", "--max-steps"):
        assert flag in text
    assert "a lone robot's run repeatable, not a team's" in text  # what a seed fixes


def test_one_default_routing_everywhere():
    assert RunConfig(robots=1, comm_range=1).routing == ROUTINGS[0] == "aodv"
    assert (
        sweepfile.SweepSpec.of(robots=(1,), comm_range=(1.0,), laser_range=(2.0,)).base.routing
        == "aodv"
    )
    args = net_up_parser().parse_args(["n1", "--robots", "2", "--comm-range", "5"])
    assert args.routing == "aodv"


def test_net_up_takes_the_network_options_with_runs_checks():
    run = {a.dest: a for a in run_parser()._actions}
    up = {a.dest: a for a in net_up_parser()._actions}
    assert {"comm_range", "routing", "loss_pct", "delay_ms", "time_scale"} <= {
        o.name for o in NET_OPTIONS
    }
    for opt in NET_OPTIONS:
        a, b = run[opt.name], up[opt.name]
        assert (a.option_strings, a.choices, a.default, a.help) == (
            b.option_strings, b.choices, b.default, b.help,
        )  # fmt: skip
    with pytest.raises(UsageError, match="at most 100"):
        net_up_parser().parse_args(["n1", "--robots", "2", "--comm-range", "5", "--loss", "101"])


@pytest.mark.parametrize("path", sorted((REPO / "testbed" / "experiments").glob("*.toml")),
                         ids=lambda p: p.name)  # fmt: skip
def test_each_planned_run_of_each_experiment_round_trips(path):
    runs = sweepfile.expand(sweepfile.load(path))
    if any(run.config.robot == "cpp" for run in runs) and unbuilt_reason() is not None:
        pytest.skip(f"{path.name} asks for the C++ robot: {unbuilt_reason()}")
    for run in runs:
        argv = run_argv([], run.config, Path("/x") / run.run_id)
        assert parse_run(argv[: argv.index("--quiet")]) == run.config, run.run_id
        # and from the plan sweep.json records (what a Slurm task reads)
        assert run_argv([], plan_dict(run.config), Path("/x") / run.run_id) == argv


GOOD = """
[grid]
robots = [1, 2]
comm_range = [5]
laser_range = [2.0]
[run]
"""


def bad_values(opt):
    if opt.choices:
        return ['"nope"']
    if opt.kind is bool:
        return ['"yes"']
    if opt.kind is str:
        return ["3"]
    out = ['"x"', "true"]
    if opt.above is not None:
        out.append(f"{opt.above:g}")
    if opt.minimum is not None:
        out.append(f"{opt.minimum - 1:g}")
    if opt.maximum is not None:
        out.append(f"{opt.maximum * 2 + 1:g}")  # :g rounds 1e7 + 1 to the maximum itself
    if opt.kind is int:
        out.append("1.5")
    return out


@pytest.mark.parametrize("opt", [o for o in OPTIONS if o.sweep], ids=lambda o: o.name)
def test_sweep_file_checks_come_from_the_table(opt):
    for bad in bad_values(opt):
        for table in sorted(opt.sweep):
            text = GOOD.replace("[run]", "")
            if table == "grid":
                text = text.replace(f"{opt.name} = ", "_old = ")
                text = text.replace("[grid]", f"[grid]\n{opt.name} = [{bad}]")
                text = text.replace("_old = [1, 2]\n", "").replace("_old = [5]\n", "")
                text = text.replace("_old = [2.0]\n", "")
                key = f"grid.{opt.name}"
            else:
                text += f"[run]\n{opt.name} = {bad}\n"
                key = f"run.{opt.name}"
            with pytest.raises(UsageError) as e:
                sweepfile.parse(tomllib.loads(text), "s.toml")
            assert str(e.value).startswith(f"sweep file s.toml: {key}:"), (bad, str(e.value))


def test_a_grid_dimension_is_declared_once_on_its_option():
    """The sweep side holds no field of its own per dimension: SweepSpec names no RunConfig
    field, every option a sweep may vary carries its GridDim, and a spec built from the
    table alone expands with one point value per dimension, in the table's order."""
    names = {f.name for f in dataclasses.fields(RunConfig)}
    assert not names & {f.name for f in dataclasses.fields(sweepfile.SweepSpec)}
    grid = [o for o in OPTIONS if "grid" in o.sweep]
    assert grid and all(o.grid is not None for o in grid)
    assert len({o.grid.order for o in grid}) == len(grid)  # one place each in the grid
    assert tuple(o.name for o in sorted(grid, key=lambda o: o.grid.order)) == sweepfile.GRID_NAMES
    spec = sweepfile.SweepSpec.of(robots=(1, 2), comm_range=(5.0,), laser_range=(2.0,),
                                  coordination=("paper", "ours"))  # fmt: skip
    runs = sweepfile.expand(spec)
    assert len(runs) == 4 and all(len(r.point) == len(grid) for r in runs)
    assert {r.run_id for r in runs} == {"n01-c5-l2-paper-k1", "n01-c5-l2-k1",
                                        "n02-c5-l2-paper-k1", "n02-c5-l2-k1"}  # fmt: skip
    # the variants of a point share its seed; another team size has its own
    seeds = {(r.config.robots, r.config.coordination): r.config.seed for r in runs}
    assert seeds[1, "paper"] == seeds[1, "ours"] != seeds[2, "ours"]


def test_the_report_reads_both_shapes_of_a_sweeps_spec():
    from testbed.analysis.sweepinfo import _spec_lines
    from testbed.files.sweepstate import SweepState

    spec = sweepfile.SweepSpec.of(robots=(1, 2), comm_range=(5.0, 20.0), laser_range=(2.0,),
                                  runs=2, time_scale=4.0)  # fmt: skip
    older = {"robots": [1, 2], "comm_range": [5.0, 20.0], "laser_range": [2.0],
             "loss_pct": [0.0], "delay_ms": [0.0], "runs": 2, "time_scale": 4.0,
             "routing": "aodv", "time_scale_by_robots": {}}  # fmt: skip
    new = SweepState.from_dict({"sweep_file": "s.toml", "spec": spec.to_dict()})
    old = SweepState.from_dict({"sweep_file": "s.toml", "spec": older})
    assert _spec_lines(new) == _spec_lines(old)
    assert "teams [1, 2], ranges [5.0, 20.0] m, lasers [2.0] m, loss [0.0] %" in _spec_lines(new)[0]


def test_the_robots_parameters_are_declared_once_in_node_launch():
    """A run passes each robot parameter through by name (node.launch.run_params); its run
    option, the robot's own config and the robot's command line take the default and the
    bounds from NodeArgs' one declaration, so they cannot disagree."""
    from node.launch import NodeArgs, bounds, parser, run_params
    from node.robot import RobotConfig
    from testbed.files.runconfig import BY_NAME

    robot_defaults = {f.name: f.default for f in dataclasses.fields(RobotConfig)}
    run_defaults = {f.name: f.default for f in dataclasses.fields(RunConfig)}
    flags = {a.dest: a for a in parser()._actions}
    for name, f in run_params().items():
        assert run_defaults[name] == f.default == flags[name].default, name
        if name in robot_defaults:
            assert robot_defaults[name] == f.default, name
        opt = BY_NAME.get(name)
        if opt is None or name == "time_scale":  # not an option, or the run's own clock
            continue
        for key, value in bounds(name).items():
            if key != "default":
                assert getattr(opt, key) == value, (name, key)
    assert "laser_rays" in run_params() and BY_NAME["laser_rays"].minimum == 4
    assert NodeArgs(robot=1, robots=1, body="b").laser_rays == BY_NAME["laser_rays"].default


def test_maps_pubsub_is_refused_without_a_pubsub_middleware(capsys):
    """--maps pubsub with a middleware that has no topics: one line, exit 2, from `testbed
    run` and from a sweep file (grid or run), before anything is made."""
    assert parse_run(["--robots", "2", "--comm-range", "5"]).maps == "flood"
    for mw in ("zenoh", "dds"):
        cfg = parse_run(["--robots", "2", "--comm-range", "5", "--maps", "pubsub",
                         "--middleware", mw])  # fmt: skip
        assert (cfg.maps, cfg.middleware) == ("pubsub", mw)
    for mw in ("nanomsg", "zeromq", "zeromq-reqrep"):
        with pytest.raises(UsageError) as e:
            parse_run(["--robots", "2", "--comm-range", "5", "--maps", "pubsub",
                       "--middleware", mw])  # fmt: skip
        assert str(e.value) == (
            f"--maps pubsub needs --middleware zenoh or dds (not {mw}): maps are published "
            "on their topics"
        )
    with pytest.raises(UsageError, match="--maps pubsub needs --middleware zenoh or dds"):
        parse_run(["--robots", "2", "--comm-range", "5", "--maps", "pubsub"])  # nanomsg
    out = subprocess.run(
        [sys.executable, "-m", "testbed.cli", "run", "--robots", "2", "--comm-range", "5",
         "--maps", "pubsub", "--middleware", "zeromq", "--out", "/nonexistent/mwm"],
        capture_output=True, text=True, cwd=REPO, timeout=60,
    )  # fmt: skip
    assert out.returncode == 2
    assert out.stderr.strip().splitlines() == [
        "testbed: error: --maps pubsub needs --middleware zenoh or dds (not zeromq): maps are "
        "published on their topics"
    ]
    grid = GOOD.replace("[grid]", '[grid]\nmaps = ["flood", "pubsub"]')
    with pytest.raises(UsageError, match=r"s.toml: grid.maps: pubsub needs middleware zenoh or "
                       r"dds \(the sweep has nanomsg\)"):  # fmt: skip
        sweepfile.parse(tomllib.loads(grid), "s.toml")
    ok = grid.replace("[grid]", '[grid]\nmiddleware = ["zenoh", "dds"]')
    runs = sweepfile.expand(sweepfile.parse(tomllib.loads(ok), "s.toml"))
    assert {(r.config.maps, r.config.middleware) for r in runs} == {
        (m, mw) for m in ("flood", "pubsub") for mw in ("zenoh", "dds")
    }
    assert any("-zenoh-pubsub-" in r.run_id for r in runs), [r.run_id for r in runs]
    fixed = GOOD + 'maps = "pubsub"\nmiddleware = "zeromq"\n'
    with pytest.raises(UsageError, match="s.toml: run.maps: pubsub needs middleware"):
        sweepfile.parse(tomllib.loads(fixed), "s.toml")
