"""Which robot program a run starts (testbed.run.robotchoice, `--robot`), and the C++
robot's command line against the Python robot's (node.launch.NodeArgs): the same argv is
accepted by both, bad arguments refused by both in one line with exit status 2."""

import dataclasses
import os
import subprocess
import sys

import pytest

from common.errors import UsageError
from node.launch import NodeArgs
from node.native import TB_ROBOT, unbuilt_reason
from testbed import cli
from testbed.run import robotchoice
from testbed.run.arguments import config_from_args

NNG = ("nanomsg",)
BOTH = ("nanomsg", "zeromq")


def test_auto_takes_the_cpp_robot_where_built_and_it_carries_the_run():
    assert robotchoice.choose("auto", "nanomsg", "flood", built=True, carries=NNG) == (
        "cpp", "auto: built and carries nanomsg")  # fmt: skip
    assert robotchoice.choose("auto", "zeromq", "flood", built=True, carries=BOTH) == (
        "cpp", "auto: built and carries zeromq")  # fmt: skip


@pytest.mark.parametrize(
    "middleware,maps,built,why",
    [("nanomsg", "flood", False, "not built"), ("zenoh", "flood", True, "--middleware zenoh"),
     ("zenoh", "pubsub", True, "--middleware zenoh"), ("nanomsg", "pubsub", True, "--maps"),
     ("zeromq", "flood", True, "carries nanomsg, not --middleware zeromq")],
)  # fmt: skip
def test_auto_falls_back_to_python_and_says_why(middleware, maps, built, why):
    impl, reason = robotchoice.choose("auto", middleware, maps, built=built, carries=NNG)
    assert impl == "python" and reason.startswith("auto: ") and why in reason


def test_python_on_request_and_cpp_refused_where_it_cannot_run():
    assert robotchoice.choose("python", "nanomsg", "flood", built=True, carries=BOTH)[0] == "python"
    assert robotchoice.choose("cpp", "nanomsg", "flood", built=True, carries=BOTH)[0] == "cpp"
    with pytest.raises(ValueError, match="carries nanomsg and zeromq, not --middleware dds"):
        robotchoice.choose("cpp", "dds", "flood", built=True, carries=BOTH)


def test_a_run_asking_for_cpp_with_another_middleware_is_refused_before_it_starts():
    argv = ["run", "--robots", "2", "--comm-range", "5", "--laser-range", "2", "--middleware",
            "zenoh", "--robot", "cpp", "--out", "/x"]  # fmt: skip
    with pytest.raises(UsageError, match="--robot cpp"):
        config_from_args(cli.build_parser(["run"]).parse_args(argv))


needs_binary = pytest.mark.skipif(unbuilt_reason() is not None, reason=str(unbuilt_reason()))


def tb_robot(argv: list[str]) -> subprocess.CompletedProcess:
    return subprocess.run([str(TB_ROBOT), *argv], capture_output=True, text=True, timeout=10)


@needs_binary
def test_the_runners_argv_is_accepted_by_both_robots(tmp_path):
    args = NodeArgs(robot=3, robots=5, body=str(tmp_path / "none.sock"), map_size=(300, 200),
                    cell=0.05, laser_range=5.0, time_scale=7.5, timer_phase=3,
                    coordination="paper", flood="blind",
                    events=str(tmp_path / "e.jsonl"))  # fmt: skip
    assert NodeArgs.parse(args.to_argv()) == args
    p = tb_robot(args.to_argv())  # parsed, then the body link is not there: cannot start
    assert p.returncode == 1 and p.stderr.count("\n") == 1
    assert "cannot start" in p.stderr and "none.sock" in p.stderr


BAD = [
    ["--robot", "r0", "--robots", "2", "--body", "x"],
    ["--robot", "r1", "--robots", "0", "--body", "x"],
    ["--robot", "r1", "--robots", "2"],
    ["--robot", "r1", "--robots", "2", "--body", "x", "--laser-range", "nan"],
    ["--robot", "r1", "--robots", "2", "--body", "x", "--map-size", "10x"],
    ["--robot", "r1", "--robots", "2", "--body", "x", "--flood", "storm"],
    ["--robot", "r1", "--robots", "2", "--body", "x", "--no-such-flag", "1"],
    ["--robot", "r1", "--robots", "2", "--body", "x", "--laser-rays", "3"],
    ["--robot", "r1", "--robots", "2", "--body", "x", "--snapshots", "1,x"],
    ["--robot", "r1", "--robots", "2", "--body", "x", "--snapshots", "1__0"],
]


@needs_binary
@pytest.mark.parametrize("argv", BAD, ids=lambda a: " ".join(a[-2:]))
def test_bad_arguments_are_refused_by_both_in_one_line(argv):
    with pytest.raises(SystemExit) as e:
        NodeArgs.parse(argv)
    assert e.value.code == 2
    p = tb_robot(argv)
    assert p.returncode == 2 and p.stderr.count("\n") == 1 and p.stderr.startswith("node: ")


@needs_binary
@pytest.mark.parametrize("extra", [["--middleware", "zenoh"],
                                   ["--middleware", "dds", "--maps", "pubsub"],
                                   ["--role", "display", "--out-dir", "/nonexistent/d",
                                    "--middleware", "zenoh", "--maps", "pubsub"]])  # fmt: skip
def test_the_cpp_robot_refuses_what_only_python_runs(extra):
    p = tb_robot(["--robot", "r1", "--robots", "2", "--body", "x", *extra])
    assert p.returncode == 2 and p.stderr.count("\n") == 1 and "python" in p.stderr.lower()


@needs_binary
@pytest.mark.parametrize("extra", [[], ["--out-dir", "/nonexistent/d", "--snapshots", "1,x"]])
def test_a_display_without_its_directory_or_with_bad_steps_is_refused_by_both(extra):
    argv = ["--robot", "r3", "--robots", "2", "--body", "x", "--role", "display", *extra]
    p = tb_robot(argv)
    assert p.returncode == 2 and p.stderr.count("\n") == 1 and p.stderr.startswith("node: ")
    for module in ("node", "node.nativedisplay"):  # the Python display; the C++ one's starter
        py = subprocess.run([sys.executable, "-m", module, *argv], capture_output=True,
                            text=True, timeout=60)  # fmt: skip
        assert py.returncode == 2 and py.stderr.count("\n") == 1, (module, py.stderr)


@needs_binary
def test_the_built_robot_says_what_it_carries():
    """nanomsg always; ZeroMQ exactly where libzmq3-dev was there when make setup built it."""
    p = tb_robot(["--middlewares"])
    assert p.returncode == 0 and p.stderr == ""
    carries = p.stdout.split()
    zmq_there = os.path.exists("/usr/include/zmq.h")
    assert carries == (["nanomsg", "zeromq"] if zmq_there else ["nanomsg"])
    assert robotchoice.carried_middlewares() == tuple(carries)


def test_robot_choice_is_recorded_in_the_result_type():
    from testbed.files.resultfile import RunResult

    names = {f.name for f in dataclasses.fields(RunResult)}
    assert {"robot", "robot_reason"} <= names
