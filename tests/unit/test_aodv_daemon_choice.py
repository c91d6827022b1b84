"""Which AODV daemon a run starts (testbed.run.daemonchoice, `--aodv-daemon`): the choice,
the option through the one table (run, net up, argv, result.json), and what the topology makes
of it (topology.routing: the program, the fork server or not, the refusal before bring-up).

The machine's own build is asked where a test needs "built" or "not built" for real:
TESTBED_TB_AODV names the compiled daemon, here an executable that exists (/bin/true) or a path
that does not."""

import dataclasses
import os
import re
import subprocess
import sys
import tomllib

import pytest

from common.errors import UsageError
from testbed import PROJECT_ROOT, cli
from testbed.files.resultfile import RunResult
from testbed.files.runconfig import BY_NAME, RunConfig, to_argv
from testbed.run import daemonchoice
from testbed.run.arguments import network_fields, refusal
from tests.unit.test_run_options import net_up_parser, parse_run
from topology import names, routing, state
from topology.kernel import netns
from topology.spec import AODV_DAEMONS, NetworkSpec

MISSING = "/nonexistent/tb-aodv"
REASON = "C++ AODV daemon not built: g++ failed on native/aodv/daemon (above)"


@pytest.fixture
def built(monkeypatch):
    """The compiled daemon is 'there': an executable file."""
    monkeypatch.setenv(routing.TB_AODV_ENV, "/bin/true")


@pytest.fixture
def absent(monkeypatch):
    monkeypatch.setenv(routing.TB_AODV_ENV, MISSING)


def test_auto_takes_the_compiled_daemon_where_built_else_python_saying_why():
    assert daemonchoice.choose("auto", "aodv", built=True) == ("cpp", "auto: tb-aodv built")
    daemon, why = daemonchoice.choose("auto", "aodv", built=False, unbuilt=REASON)
    assert daemon == "python" and why == f"auto: the compiled daemon is not built: {REASON}"
    daemon, why = daemonchoice.choose("auto", "aodv", built=False, unbuilt=None)
    assert daemon == "python" and "tb-aodv not built (make setup builds it" in why


def test_cpp_insists_and_python_asks_for_the_reference():
    assert daemonchoice.choose("cpp", "aodv", built=True) == ("cpp", "cpp: asked for")
    with pytest.raises(ValueError, match=f"--aodv-daemon cpp: .*{re.escape(REASON)}"):
        daemonchoice.choose("cpp", "aodv", built=False, unbuilt=REASON)
    for built in (True, False):
        assert daemonchoice.choose("python", "aodv", built=built) == ("python", "python: asked for")
    with pytest.raises(ValueError, match="one of auto, cpp, python"):
        daemonchoice.choose("rust", "aodv", built=True)


@pytest.mark.parametrize("other", ["babel", "batman", "oracle", "none"])
def test_another_routing_runs_no_aodv_daemon_and_refuses_nothing(other):
    for asked in daemonchoice.CHOICES:
        assert daemonchoice.choose(asked, other, built=False) == (
            None, f"routing {other} runs no AODV daemon",
        )  # fmt: skip
    assert daemonchoice.spec_daemon("cpp", other) == AODV_DAEMONS[0]


def test_the_machine_is_asked_when_not_told(built, monkeypatch):
    assert routing.aodv_built() and routing.aodv_unbuilt_reason() is None
    assert daemonchoice.choose("auto", "aodv")[0] == "cpp"
    monkeypatch.setenv(routing.TB_AODV_ENV, MISSING)
    assert not routing.aodv_built()
    daemon, why = daemonchoice.choose("auto", "aodv")
    assert daemon == "python" and why.startswith("auto: the compiled daemon is not built: ")
    unbuilt = routing.aodv_unbuilt_reason()
    assert unbuilt is None or unbuilt in why  # make setup's line, where it wrote one


def test_a_file_that_is_not_executable_is_not_built(tmp_path, monkeypatch):
    plain = tmp_path / "tb-aodv"
    plain.write_text("")
    monkeypatch.setenv(routing.TB_AODV_ENV, str(plain))
    assert not routing.aodv_built()


# ------------------------------------------------------------------ the option table


def test_the_option_is_in_the_table_for_run_net_up_and_sweeps():
    opt = BY_NAME["aodv_daemon"]
    assert opt.default == "auto" and opt.choices == daemonchoice.CHOICES == (
        "auto",
        "cpp",
        "python",
    )
    assert opt.net and opt.newer and opt.flag == "--aodv-daemon"
    assert RunConfig(robots=1, comm_range=1).aodv_daemon == "auto"
    args = net_up_parser().parse_args(["n1", "--robots", "2", "--comm-range", "5"])
    assert args.aodv_daemon == "auto"
    args = net_up_parser().parse_args(["n1", "--robots", "2", "--comm-range", "5",
                                       "--aodv-daemon", "python"])  # fmt: skip
    assert args.aodv_daemon == "python"


@pytest.mark.parametrize("asked", ["auto", "python"])
def test_the_option_round_trips_through_argv_and_config_json(asked):
    cfg = parse_run(["--robots", "2", "--comm-range", "5", "--aodv-daemon", asked])
    assert cfg.aodv_daemon == asked
    assert parse_run(to_argv(cfg)) == cfg
    assert RunConfig.from_dict(cfg.to_dict()) == cfg
    assert ("--aodv-daemon" in to_argv(cfg)) == (asked != "auto")  # newer: only when set


def test_an_unknown_daemon_is_one_line_and_status_2():
    p = subprocess.run(
        [sys.executable, "-m", "testbed", "run", "--robots", "1", "--comm-range", "5",
         "--aodv-daemon", "rust", "--out", "/nonexistent/x"],
        capture_output=True, text=True, timeout=60, cwd=PROJECT_ROOT,
    )  # fmt: skip
    assert p.returncode == 2 and "--aodv-daemon" in p.stderr, p.stderr
    assert "Traceback" not in p.stderr


def test_cpp_without_the_program_is_refused_at_the_start(absent):
    cfg = RunConfig(robots=2, comm_range=5, aodv_daemon="cpp")
    field, why = refusal(cfg) or ("", "")
    assert field == "aodv_daemon" and why.startswith("--aodv-daemon cpp: ")
    assert refusal(cfg, program=False) is None  # a sweep planned for another machine
    assert refusal(dataclasses.replace(cfg, routing="babel")) is None
    with pytest.raises(UsageError, match="--aodv-daemon cpp"):
        parse_run(["--robots", "2", "--comm-range", "5", "--aodv-daemon", "cpp"])
    with pytest.raises(ValueError, match="--aodv-daemon cpp"):
        network_fields(cfg)


def test_cpp_without_the_program_is_one_line_and_status_2_from_the_cli():
    env = dict(os.environ, **{routing.TB_AODV_ENV: MISSING})
    p = subprocess.run(
        [sys.executable, "-m", "testbed", "run", "--robots", "1", "--comm-range", "5",
         "--aodv-daemon", "cpp", "--out", "/nonexistent/x"],
        capture_output=True, text=True, timeout=60, cwd=PROJECT_ROOT, env=env,
    )  # fmt: skip
    assert p.returncode == 2 and p.stderr.count("\n") == 1, p.stderr
    assert "--aodv-daemon cpp" in p.stderr and MISSING not in p.stdout


def test_net_up_refuses_cpp_without_the_program_in_one_line():
    env = dict(os.environ, **{routing.TB_AODV_ENV: MISSING})
    p = subprocess.run(
        [sys.executable, "-m", "testbed", "net", "up", "tcwnone", "--robots", "2",
         "--comm-range", "5", "--aodv-daemon", "cpp"],
        capture_output=True, text=True, timeout=60, cwd=PROJECT_ROOT, env=env,
    )  # fmt: skip
    assert p.returncode == 2 and p.stderr.count("\n") == 1, p.stderr
    assert "--aodv-daemon cpp" in p.stderr or "compiled AODV daemon" in p.stderr, p.stderr


def test_network_fields_hand_the_spec_the_daemon_that_runs(built, monkeypatch):
    cfg = RunConfig(robots=2, comm_range=5)
    assert network_fields(cfg)["aodv_daemon"] == "cpp"
    assert network_fields(dataclasses.replace(cfg, aodv_daemon="python"))["aodv_daemon"] == "python"
    monkeypatch.setenv(routing.TB_AODV_ENV, MISSING)
    assert network_fields(cfg)["aodv_daemon"] == "python"
    assert network_fields(dataclasses.replace(cfg, routing="babel"))["aodv_daemon"] == "python"


# ------------------------------------------------------------------ the topology


def spec(daemon: str, routing_name: str = "aodv") -> NetworkSpec:
    return NetworkSpec(name="n1", positions=((0, 0), (5, 0)), comm_range=10,
                       routing=routing_name, aodv_daemon=daemon)  # fmt: skip


def test_the_spec_holds_a_daemon_that_runs_and_keeps_it_in_the_state_file():
    assert NetworkSpec(name="n1", positions=((0, 0),), comm_range=1).aodv_daemon == "python"
    for bad in ("auto", "CPP", ""):
        with pytest.raises(ValueError, match="unknown AODV daemon"):
            spec(bad)
    s = spec("cpp")
    assert state.spec_from_dict(state.spec_to_dict(s)) == s
    older = state.spec_to_dict(spec("python"))
    del older["aodv_daemon"]  # a state file written before the option
    assert state.spec_from_dict(older).aodv_daemon == "python"


def test_both_daemons_get_the_same_arguments(built):
    cpp = routing.argv_for(spec("cpp"), 2, "/run/x")
    py = routing.argv_for(spec("python"), 2, "/run/x")
    assert cpp is not None and py is not None
    assert cpp[0] == "/bin/true" and py[:3] == [sys.executable, "-m", "aodv"]
    # the compiled daemon enters robot 2's namespace itself: no `ip netns exec` before it
    assert cpp[1:3] == ["--netns", names.robot_ns("n1", 2)]
    assert netns.popen_argv(names.robot_ns("n1", 2), cpp) == cpp
    assert cpp[3:] == py[3:] == routing.aodv_args(2, "/run/x", spec("cpp"))
    assert routing.aodv_command("cpp") == ["/bin/true"]
    assert routing.aodv_command("python") == routing.aodv_command() == py[:3]


def test_only_the_python_daemon_is_forked_from_the_fork_server(built):
    assert routing.forkable(spec("python")) is routing.FORKABLE["aodv"]
    assert routing.forkable(spec("cpp")) is None
    assert routing.forkable(spec("cpp", "babel")) is None
    assert routing.preflight_refusal(spec("cpp")) is None


def test_a_missing_program_is_refused_before_bring_up_in_one_line(absent):
    why = routing.preflight_refusal(spec("cpp"))
    assert why and why.startswith(f"the compiled AODV daemon {MISSING} is not there: ")
    assert "\n" not in why
    assert routing.preflight_refusal(spec("python")) is None
    assert routing.preflight_refusal(spec("cpp", "babel")) is None


def test_the_default_binary_is_builds_tb_aodv(monkeypatch):
    monkeypatch.delenv(routing.TB_AODV_ENV, raising=False)
    assert routing.aodv_binary() == os.path.join(PROJECT_ROOT, "build", "tb-aodv")
    assert routing.TB_AODV_UNBUILT.name == "tb-aodv.unbuilt"


# ------------------------------------------------------------------ result.json


def test_result_json_records_the_daemon_and_why():
    names = [f.name for f in dataclasses.fields(RunResult)]
    assert names.index("aodv_daemon") + 1 == names.index("aodv_daemon_reason")
    config = {"robots": 1, "comm_range": 5.0, "laser_range": 2.0}
    doc = {"status": "complete", "config": config, "aodv_daemon": "cpp",
           "aodv_daemon_reason": "auto: tb-aodv built"}  # fmt: skip
    r = RunResult.from_json(doc)
    assert (r.aodv_daemon, r.aodv_daemon_reason) == ("cpp", "auto: tb-aodv built")
    again = r.to_json()
    assert again["aodv_daemon"] == "cpp" and again["aodv_daemon_reason"] == "auto: tb-aodv built"
    older = RunResult.from_json({"status": "complete", "config": config})
    assert older.aodv_daemon is None and older.aodv_daemon_reason == ""


def test_the_cli_parser_builds():  # the flag on both commands' --help
    for cmd in (["run"], ["net"]):
        cli.build_parser(cmd)
    assert "--aodv-daemon" in " ".join(net_up_parser().format_help().split())


def test_a_sweep_may_vary_the_daemon_and_its_run_ids_say_which():
    from testbed.sweep import file as sweepfile

    text = """
[grid]
robots = [2]
comm_range = [5]
laser_range = [2.0]
aodv_daemon = ["python", "auto"]
"""
    runs = sweepfile.expand(sweepfile.parse(tomllib.loads(text), "s.toml"))
    assert [r.config.aodv_daemon for r in runs] == ["python", "auto"]
    ids = [r.run_id for r in runs]
    assert [part for i in ids for part in i.split("-") if part.startswith("aodv")] == [
        "aodvpython", "aodvauto",
    ], ids  # fmt: skip
    fixed = text.replace('aodv_daemon = ["python", "auto"]', '[run]\naodv_daemon = "python"')
    (run,) = sweepfile.expand(sweepfile.parse(tomllib.loads(fixed)))
    assert run.config.aodv_daemon == "python" and "aodv" not in run.run_id  # not a dimension
