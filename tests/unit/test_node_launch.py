"""The robot's command line (node.launch): the dataclass and the parser cannot drift apart."""

import dataclasses

import pytest

from node.launch import NodeArgs, parser


def test_every_field_round_trips_through_argv_with_non_default_values():
    args = NodeArgs(
        robot=7, robots=9, body="/run/x/body.sock", role="display", events="/tmp/e.jsonl",
        map_size=(300, 250), cell=0.1, laser_range=1.5, laser_rays=180, speed=0.075,
        radius=0.2, plan_period=15, map_period=7, time_scale=3.75, timer_phase=11,
        iface="", flood_port=6000, flood="blind", coordination="paper", goal_port=6001,
        middleware="zenoh", maps="pubsub", bind="127.0.0.1",
        out_dir="/tmp/d", snapshots=frozenset({600, 200}), video_every=4,
    )  # fmt: skip
    defaults = NodeArgs(robot=1, robots=1, body="b")
    for f in dataclasses.fields(NodeArgs):
        assert getattr(args, f.name) != getattr(defaults, f.name), f.name  # all non-default
    assert NodeArgs.parse(args.to_argv()) == args


def test_floats_round_trip_exactly():
    args = NodeArgs(robot=1, robots=1, body="b", time_scale=0.1 + 0.2, speed=1 / 3)
    assert NodeArgs.parse(args.to_argv()) == args


def test_parser_options_are_the_dataclass_fields():
    dests = {a.dest for a in parser()._actions if a.dest != "help"}
    assert dests == {f.name for f in dataclasses.fields(NodeArgs)}


def test_defaults_agree():
    parsed = NodeArgs.parse(["--robot", "r1", "--robots", "1", "--body", "b"])
    assert parsed == NodeArgs(robot=1, robots=1, body="b")


def test_bad_argument_is_one_line_and_exit_2(capsys):
    with pytest.raises(SystemExit) as e:
        NodeArgs.parse(["--robot", "r1", "--robots", "0", "--body", "b"])
    assert e.value.code == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        "node: argument --robots: --robots must be greater than 0, not 0"
    ]
