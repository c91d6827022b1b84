"""Reading one result.json takes a handful of modules (issue 56): the reader is the ground
floor's (testbed/files), and neither it nor the analysis's run reader pulls in OpenCV, the
web server, the robot's planner or the step core. Counted in a fresh interpreter, from
sys.modules, after the file is read."""

import json
import os
import subprocess
import sys

import pytest

from testbed import PROJECT_ROOT
from testbed.files.resultfile import RunResult

PROJECT = ("common", "node", "topology", "aodv", "testbed")
# Project modules loaded, packages' __init__ not counted (they hold a docstring or a path):
# the type's four, common's bounded reader, paths and time-scale bounds, topology's constants
# (spec, names, the routing protocols' registry: data only); the analysis adds its run reader
# and the relay-lag file's, and the types of medium.json and of the run directory's layout.
BUDGET = {"resultfile": 10, "analysis.runs": 14}
HEAVY = ("cv2", "numpy", "matplotlib", "http.server", "subprocess")

# Prints the project modules loaded and the heavy ones, as JSON.
PROBE = """
import json, sys
{read}
mods = [m for m in sys.modules if m.split(".")[0] in {project!r}]
pkgs = [m for m in mods if getattr(sys.modules[m], "__path__", None) is not None]
print(json.dumps({{"modules": sorted(set(mods) - set(pkgs)), "packages": sorted(pkgs),
                  "heavy": [h for h in {heavy!r} if h in sys.modules]}}))
"""
READERS = {
    "resultfile": "from testbed.files.resultfile import RunResult\n"
    "RunResult.from_json(sys.argv[1])",
    "analysis.runs": "from testbed.analysis.runs import load_run\nload_run(sys.argv[1])",
}


def loaded(read: str, run_dir: str) -> dict:
    code = PROBE.format(read=read, project=PROJECT, heavy=HEAVY)
    env = dict(os.environ, PYTHONPATH=PROJECT_ROOT)
    p = subprocess.run([sys.executable, "-c", code, run_dir], capture_output=True, text=True,
                       env=env, cwd=PROJECT_ROOT, timeout=60, check=True)  # fmt: skip
    return json.loads(p.stdout)


@pytest.fixture
def run_dir(tmp_path):
    result = RunResult.from_json(
        {"config": {"robots": 2, "comm_range": 10.0, "laser_range": 2.0}, "status": "ok",
         "steps": 900, "robots": {"r1": {"finish_step": 850}, "r2": {"finish_step": 880}}}
    )  # fmt: skip
    result.write(tmp_path)
    assert json.loads((tmp_path / "result.json").read_text())["status"] == "ok"
    return str(tmp_path)


@pytest.mark.parametrize("reader", sorted(READERS))
def test_reading_one_result_loads_a_handful_of_modules(reader, run_dir):
    got = loaded(READERS[reader], run_dir)
    assert not got["heavy"], f"reading a result.json loads {got['heavy']}"
    assert len(got["modules"]) <= BUDGET[reader], got["modules"]


# The option table: options.py's terms, and runconfig.py's RunConfig with the robot's own
# declarations of its parameters (node.argsdecl), never node.launch's planner and step core
# (30 modules, numpy and ctypes before node.argsdecl). runconfig's 18: itself, options,
# failures, isolation, result.json's config and its four (resultconfig's), common's four,
# topology's three constants, node.argsdecl with displaysteps and timing.
OPTION_TABLE = {"testbed.files.options": 3, "testbed.files.runconfig": 18}
NEVER_IN_OPTIONS = ("numpy", "ctypes", "cv2")


@pytest.mark.parametrize("module", sorted(OPTION_TABLE))
def test_the_option_table_loads_no_planner_numpy_or_ctypes(module):
    code = PROBE.format(read=f"import {module}", project=PROJECT, heavy=NEVER_IN_OPTIONS)
    env = dict(os.environ, PYTHONPATH=PROJECT_ROOT)
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                       cwd=PROJECT_ROOT, timeout=60, check=True)  # fmt: skip
    got = json.loads(p.stdout)
    assert not got["heavy"], f"importing {module} loads {got['heavy']}"
    assert "node.launch" not in got["modules"], got["modules"]
    assert len(got["modules"]) <= OPTION_TABLE[module], got["modules"]
