"""Sweeps that must be refused before anything is made: another sweep's directory, a grid
too large to hold, a sweep file that is not text, an --out that is a file, maps that a run
would refuse. One line on stderr, exit status 2, no directory or lock file made, and the
directory of an earlier sweep exactly as it was. With the stand-in for `testbed run` of
tests/unit/test_sweep_runner.py; no root."""

import json
import resource
import subprocess
import sys
import textwrap
from pathlib import Path

from tests.unit.test_sweep_runner import env, results, run_sweep  # noqa: F401 (fixture)

REPO = Path(__file__).resolve().parents[2]

OTHER = """
[grid]
robots = [4]
comm_range = [5]
laser_range = [2.0]

[run]
time_scale = 5
max_steps = 500
"""


def snapshot(out: Path) -> dict[str, int]:
    """Every file under `out` with its modification time."""
    return {str(p.relative_to(out)): p.stat().st_mtime_ns for p in out.rglob("*") if p.is_file()}


def refused(r: subprocess.CompletedProcess, *words: str) -> str:
    """The one line of a refusal (exit 2), which must hold each of `words`."""
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2, r.stderr[-800:]
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr[-800:]
    for w in words:
        assert w in lines[0], lines[0]
    return lines[0]


def test_resume_with_another_sweep_file_is_refused_and_changes_nothing(env):  # noqa: F811
    out = env["tmp"] / "out"
    assert run_sweep(env, out).returncode == 0
    before = snapshot(out)
    other = env["tmp"] / "other.toml"
    other.write_text(OTHER)
    r = run_sweep(dict(env, file=other), out, "--resume")
    refused(r, f"--out {out} is the sweep of {env['file']}, not of {other}: its sweep.json "
            "plans run n01-c5-l2-k1, which this sweep file does not; resume it with its own "
            "sweep file, or give this one a new --out")  # fmt: skip
    assert snapshot(out) == before  # sweep.json not rewritten, no run of the other file
    assert len(results(out)) == 6


def test_resume_after_a_grid_change_that_alters_run_ids_is_refused(env):  # noqa: F811
    out = env["tmp"] / "out"
    assert run_sweep(env, out).returncode == 0
    before = snapshot(out)
    env["file"].write_text(env["file"].read_text().replace("comm_range = [5, 20]",
                                                           "comm_range = [6, 20]"))  # fmt: skip
    r = run_sweep(env, out, "--resume")
    refused(r, "its sweep.json plans run n01-c5-l2-k1, which this sweep file does not")
    assert snapshot(out) == before


def test_resume_after_a_setting_changed_is_refused(env):  # noqa: F811
    out = env["tmp"] / "out"
    assert run_sweep(env, out).returncode == 0
    env["file"].write_text(env["file"].read_text().replace("max_steps = 500", "max_steps = 600"))
    r = run_sweep(env, out, "--resume")
    refused(r, "max_steps", "500", "600")  # already refused before sweeps were compared


def test_a_sweep_that_only_adds_runs_resumes(env):  # noqa: F811
    out = env["tmp"] / "out"
    assert run_sweep(env, out).returncode == 0
    env["file"].write_text(env["file"].read_text().replace("runs = 1", "runs = 2"))
    r = run_sweep(env, out, "--resume")
    assert r.returncode == 0 and "12 runs, 6 done, 6 to do" in r.stderr, r.stderr[-500:]
    state = json.loads((out / "sweep.json").read_text())
    assert len(state["runs"]) == 12 == len(results(out))


def test_a_grid_of_100k_runs_is_refused_before_it_is_expanded(env, tmp_path):  # noqa: F811
    big = tmp_path / "big.toml"
    big.write_text("[grid]\nrobots = [1, 2]\ncomm_range = [5, 20]\nlaser_range = [2.0]\n"
                   "runs = 25000\n")  # fmt: skip
    out = tmp_path / "out"
    r = run_sweep(dict(env, file=big), out)
    refused(r, "grid: 100,000 runs (2 robots x 2 comm_range x 25000 runs); a sweep has at "
            "most 10,000: split it into several sweep files")  # fmt: skip
    assert not out.exists()
    # The check costs nothing: a trillion runs are refused as fast, in a few MB.
    huge = tmp_path / "huge.toml"
    huge.write_text(big.read_text().replace("25000", "1000000000000"))
    code = textwrap.dedent(f"""
        import time
        from testbed.sweep import file as sweepfile
        from common.errors import UsageError
        t = time.monotonic()
        try:
            sweepfile.expand(sweepfile.load({str(huge)!r}))
        except UsageError as exc:
            # VmHWM, not ru_maxrss: exec carries pytest's own peak over into ru_maxrss
            hwm = int(open('/proc/self/status').read().split('VmHWM:')[1].split()[0]) / 1024
            print(time.monotonic() - t, hwm)
    """)
    child = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True,
                           text=True, timeout=60, preexec_fn=_capped)  # fmt: skip
    assert child.stdout.strip(), child.stderr[-300:]
    seconds, rss_mb = child.stdout.split()
    assert float(seconds) < 1.0 and float(rss_mb) < 200, child.stderr[-300:]


def _capped():  # in the child: 2 GB of address space
    resource.setrlimit(resource.RLIMIT_AS, (2 << 30, 2 << 30))


def test_a_binary_sweep_file_is_one_line(env, tmp_path):  # noqa: F811
    binary = tmp_path / "bin.toml"
    binary.write_bytes(b"[grid]\nrobots = [1]\n\xff\xfe\x00\x01garbage")
    r = run_sweep(dict(env, file=binary), tmp_path / "out")
    refused(r, f"sweep file {binary}: not a text file (UTF-8 TOML): byte 20 is 0xff")
    assert not (tmp_path / "out").exists()


def test_out_that_is_a_file_is_a_usage_error(env, tmp_path):  # noqa: F811
    f = tmp_path / "afile"
    f.write_text("x")
    r = run_sweep(env, f)
    refused(r, f"--out {f}: exists and is not a directory")


def test_a_refused_sweep_makes_no_directory_and_no_lock(env, tmp_path):  # noqa: F811
    out = env["tmp"] / "out"
    assert run_sweep(env, out).returncode == 0
    (out / ".sweep.lock").unlink()
    r = run_sweep(env, out)  # without --resume
    refused(r, "pass --resume")
    assert not (out / ".sweep.lock").exists()
    fresh = tmp_path / "fresh" / "out"
    missing = tmp_path / "missing.toml"
    missing.write_text(env["file"].read_text() + 'map = "nowhere.png"\n')
    refused(run_sweep(dict(env, file=missing), fresh), "map file", "nowhere.png does not exist")
    assert not fresh.parent.exists()


def test_every_map_of_the_grid_is_checked_before_the_first_run(env, tmp_path):  # noqa: F811
    grid = tmp_path / "maps.toml"
    office = REPO / "testbed" / "experiments" / "maps" / "office.png"
    grid.write_text(env["file"].read_text().replace(
        "runs = 1", f'runs = 1\nmap = ["empty", "{office}", "{tmp_path}/gone.png"]'))  # fmt: skip
    out = tmp_path / "out"
    r = run_sweep(dict(env, file=grid), out)
    refused(r, f"map file {tmp_path}/gone.png does not exist")
    assert not out.exists()
    assert not list(env["pids"].iterdir())  # no run was started
    laser = tmp_path / "laser.toml"
    laser.write_text(env["file"].read_text().replace("laser_range = [2.0]",
                                                     "laser_range = [2.0, 29.0]"))  # fmt: skip
    refused(run_sweep(dict(env, file=laser), out),
            "grid.laser_range on the empty terrain: --laser-range 29 is longer than the map's "
            "diagonal")  # fmt: skip


def test_a_middleware_whose_package_is_missing_refuses_the_sweep_before_any_run(env, tmp_path):  # noqa: F811
    grid = tmp_path / "middleware.toml"
    grid.write_text(env["file"].read_text().replace(
        "runs = 1", 'runs = 1\nmiddleware = ["nanomsg", "zeromq"]'))  # fmt: skip
    out = tmp_path / "out"
    code = (
        "import runpy, sys; sys.modules['zmq'] = None; "  # as if pyzmq were not installed
        f"sys.argv = ['testbed.sweep.command', {str(grid)!r}, '--out', {str(out)!r}]; "
        "runpy.run_module('testbed.sweep.command', run_name='__main__')"
    )
    r = subprocess.run([sys.executable, "-c", code], env=env["env"], cwd=REPO,
                       capture_output=True, text=True, timeout=60)  # fmt: skip
    refused(r, "sweep: --middleware zeromq needs the Python package pyzmq")
    assert not out.exists()
    assert not list(env["pids"].iterdir())  # no run was started
