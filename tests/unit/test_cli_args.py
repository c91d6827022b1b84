"""The CLI turns bad arguments into one line on stderr and exit status 2 (no root needed)."""

import subprocess
import sys

import pytest

from testbed import cli


@pytest.mark.parametrize(
    "argv, words",
    [
        (["net", "up", "a1", "--robots", "0", "--comm-range", "5"], ["at least one robot"]),
        (["net", "up", "a1", "--robots", "3", "--comm-range", "0"], ["greater than 0"]),
        (["net", "up", "a1", "--robots", "3", "--comm-range", "-2"], ["greater than 0"]),
        (["net", "up", "a1", "--robots", "3", "--comm-range", "x"], ["must be a number"]),
        (["net", "up", "a1", "--robots", "3", "--comm-range", "5", "--layout", "hex"],
         ["invalid choice", "hex"]),
        (["net", "up", "A!", "--robots", "3", "--comm-range", "5"], ["lowercase"]),
        (["net", "up", "a1", "--robots", "2", "--comm-range", "5", "--positions", "1,2"],
         ["1 positions", "--robots 2"]),
        (["net", "up", "a1", "--robots", "1", "--comm-range", "5", "--positions", "1;2"],
         ["not X,Y"]),
        (["net", "up", "a1", "--robots", "2", "--comm-range", "5", "--loss", "-1"],
         ["negative"]),
        (["net", "move", "a1", "q3", "1", "2"], ["rK"]),
        (["net", "frobnicate"], ["invalid choice"]),
        (["run", "--robots", "3", "--comm-range", "5", "--out", "/x", "--isolate", "r3:200"],
         ["--isolate", "ROBOT:STEP:STEPS"]),
        (["run", "--robots", "3", "--comm-range", "5", "--out", "/x", "--isolate", "r3:0:10"],
         ["at least 1"]),
        (["run", "--robots", "3", "--comm-range", "5", "--out", "/x", "--isolate", "r4:9:9"],
         ["--isolate names robot 4", "r1..r3"]),
        (["run", "--robots", "3", "--comm-range", "5", "--out", "/x", "--isolate", "r3:9:9",
          "--medium", "ns3-wifi"], ["--isolate needs the veth medium"]),
        ([], ["required"]),
    ],
)  # fmt: skip
def test_bad_arguments_are_one_line_exit_2(argv, words, capsys):
    assert cli.main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    for w in words:
        assert w in err[0]


def test_same_through_the_console_entry_point():
    r = subprocess.run([sys.executable, "-m", "testbed.cli", "net", "up", "a1", "--robots",
                        "-3", "--comm-range", "5"], capture_output=True, text=True)  # fmt: skip
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


def test_help_works():
    r = subprocess.run([sys.executable, "-m", "testbed.cli", "net", "up", "--help"],
                       capture_output=True, text=True)  # fmt: skip
    assert r.returncode == 0 and "--comm-range" in r.stdout


def test_a_failed_file_operation_is_one_line_naming_the_file(tmp_path, capsys):
    (tmp_path / "runs").mkdir()
    (tmp_path / "figures").write_text("a file where the report wants a directory")
    assert cli.main(["report", str(tmp_path)]) == 2  # the directory's fault: a usage error
    (err,) = capsys.readouterr().err.strip().splitlines()
    assert err == (
        f"testbed: error: {tmp_path / 'figures'}: a symbolic link or not a directory: "
        "nothing is written through it"
    )


@pytest.mark.parametrize("command", ["up", "exec", "move", "impair", "links", "down"])
def test_every_net_argument_has_help(command):
    sub = next(a for a in cli.build_parser(["net"])._actions if a.dest == "cmd")
    net_sub = next(a for a in sub.choices["net"]._actions if a.dest == "net_cmd")
    for action in net_sub.choices[command]._actions:
        assert action.help, (command, action.dest)
