"""The `testbed` command whole: `--help` says the module's description to its end, and
`python -m testbed` is the command."""

import subprocess
import sys

from testbed import cli


def test_the_description_is_the_first_paragraph_whole():
    first = cli.__doc__.split("\n\n")[0]
    assert " ".join(first.split()) == cli.DESCRIPTION
    assert cli.DESCRIPTION.endswith(".")
    assert cli.build_parser().description == cli.DESCRIPTION


def test_python_m_testbed_runs_the_command():
    r = subprocess.run([sys.executable, "-m", "testbed", "--help"], capture_output=True,
                       text=True, timeout=60)  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("usage: testbed ")
    assert "clean-up." in r.stdout
