"""The step core as the world and the Python robot load it (build/libstepcore.so, through
ctypes), checked for memory errors and undefined behaviour: `make build/asan/libstepcore.so`
builds it with AddressSanitizer and UndefinedBehaviorSanitizer, and its unit tests (every
compiled function held equal to its numpy twin on random maps, poses and scans; the world's
casts of a step in one call; its body links' commands and frames over real sockets; the
most extreme ranges, poses and goals its callers can pass, test_stepcore_extremes; the
world's compiled step, each call and whole runs of both step loops, test_step_fast and
test_step_loop_replay) run on that build, in a Python with the ASan runtime preloaded. The
build checks float-to-integer conversions too (float-cast-overflow, which
-fsanitize=undefined leaves out). The world's step (worldstep.cc) is called from the step
loop's one thread and keeps nothing between calls but its caller's struct, so it needs no
ThreadSanitizer run; the threaded callers (the robots) have theirs in
test_cpp_robot_sanitizers.
Clean means they pass and no sanitizer reported (a report stops the process). The C++ robot,
which links the same source in, has its own sanitizer runs (test_cpp_robot_sanitizers)."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
LIBRARY = REPO / "build" / "asan" / "libstepcore.so"

pytestmark = pytest.mark.skipif(shutil.which("g++") is None, reason="g++ not found")


@pytest.mark.slow
def test_the_step_core_runs_clean_under_asan_and_ubsan():
    subprocess.run(["make", "-s", str(LIBRARY.relative_to(REPO))], cwd=REPO, check=True,
                   timeout=600)  # fmt: skip
    runtime = subprocess.run(["g++", "-print-file-name=libasan.so"], capture_output=True,
                             text=True, check=True).stdout.strip()  # fmt: skip
    env = {**os.environ, "LD_PRELOAD": runtime, "TESTBED_STEPCORE_LIBRARY": str(LIBRARY),
           "ASAN_OPTIONS": "detect_leaks=0:abort_on_error=0",  # Python's own allocations
           "UBSAN_OPTIONS": "print_stacktrace=1", "PYTHONMALLOC": "malloc"}  # fmt: skip
    env.pop("TESTBED_STEPCORE", None)
    loaded = subprocess.run(
        [sys.executable, "-c", "from node import stepcore as s; print(s.NATIVE, s.LIBRARY)"],
        cwd=REPO, env=env, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert loaded.stdout.split() == ["True", str(LIBRARY)], loaded.stdout + loaded.stderr
    tests = [
        "tests/unit/test_stepcore.py",
        "tests/unit/test_world_step.py",
        "tests/unit/test_body_fast.py",
        "tests/unit/test_stepcore_extremes.py",  # any range, pose and goal a caller can pass
        "tests/unit/test_step_fast.py",  # the world's step: commands, moves, the sleep
        "tests/unit/test_step_loop_replay.py",  # both step loops over a scripted team
    ]
    proc = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *tests],
        cwd=REPO, env=env, capture_output=True, text=True, timeout=900,
    )  # fmt: skip
    out = proc.stdout + proc.stderr
    for report in ("ERROR: AddressSanitizer", "runtime error:", "SUMMARY: "):
        assert report not in out, out[-4000:]
    assert proc.returncode == 0, out[-4000:]
    assert " passed" in proc.stdout and "skipped" not in proc.stdout, proc.stdout[-2000:]
