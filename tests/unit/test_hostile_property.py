"""Issue 40, item 7: results directories built from random valid and invalid values. Every
one must give either a correct report or exactly one line and exit status 2; never a
traceback (an exception out of the CLI fails the test), never a hang (hostile_dirs.within),
never a write outside the directory (a file outside, linked from the names the report
writes, stays as it was).

The oracle (`acceptable`) is written here, apart from testbed.files.resultfile and
testbed.files.resultcheck, from docs/run-results.md's ranges: the report must be refused
exactly when it says no, and what a report prints must be the document's own numbers.
"""

import json
import math
import os
import shutil

from hypothesis import HealthCheck, event, example, given, settings
from hypothesis import strategies as st

from tests.unit import hostile_dirs as hd

SETTINGS = settings(
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)

# Values a hostile file may hold where a number belongs: anything JSON can say.
numbers = st.one_of(
    st.integers(-(10**40), 10**40),
    st.integers(-5, 5000),
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(-10.0, 5000.0),
)
anything = st.one_of(
    numbers, st.none(), st.booleans(), st.text(max_size=20), st.lists(st.integers(), max_size=3),
    st.dictionaries(st.text(max_size=3), st.integers(), max_size=2),
)  # fmt: skip
FIELDS = {
    "steps": ("steps",),
    "robots": ("config", "robots"),
    "comm_range": ("config", "comm_range"),
    "finish": ("robots", "r1", "finish_step"),
    "missed": ("deadlines_missed",),
    "stall_missed": ("host_stalls", "deadlines_missed"),
    "coverage": ("coverage_final",),
    "detail": ("status_detail",),
}
# Values a run could have written for each field (the run's robots finish at 817 and 823).
VALID = {
    "steps": st.integers(823, 100_000),
    "robots": st.integers(1, 1000),
    "comm_range": st.floats(0.01, 1e6),
    "finish": st.one_of(st.floats(0.0, 824.0), st.integers(0, 824)),
    "missed": st.integers(0, 10**6),
    "stall_missed": st.just(0),
    "coverage": st.floats(0.0, 1.0),
    "detail": st.text(max_size=40),
}


@st.composite
def changes(draw):
    """Up to three fields of result.json, each a value a run could write or anything."""
    names = draw(st.sets(st.sampled_from(sorted(FIELDS)), max_size=3))
    return {n: draw(st.one_of(VALID[n], VALID[n], numbers, anything)) for n in names}


def _number(v) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def _whole(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _too_long(v) -> bool:
    """An int of more than 30 digits: the strict reader refuses it whatever the field."""
    return _whole(v) and len(str(abs(v))) > 30


def acceptable(doc: dict) -> bool:
    """Whether result.json `doc` is one a run could have written (the fields changed)."""
    c = doc["config"]
    steps = doc.get("steps")
    if steps is not None and not (_number(steps) and steps == int(steps) and 0 <= steps <= 1e9):
        return False
    top = 1e9 if steps is None else int(steps) + 1
    if not (_whole(c.get("robots")) and 1 <= c["robots"] <= 1000):
        return False
    if not (_number(c.get("comm_range")) and 0 < c["comm_range"] <= 1e7):
        return False
    # Every step the run recorded lies within it: each robot's finish, stop and plans (the
    # others' too, when `steps` was made smaller than their finish), and the run's own.
    at = [doc.get("last_finish_step"), doc.get("mean_finish_step")]
    for robot in doc["robots"].values():
        at += [robot.get("finish_step"), robot.get("stopped_step")]
        at += [p.get("step") for p in robot.get("plans") or ()]
    if not all(s is None or (_number(s) and 0 <= s <= top) for s in at):
        return False
    missed = doc.get("deadlines_missed")
    missed = 0 if missed is None else missed
    if not (_whole(missed) and 0 <= missed <= 1001e9):
        return False
    stall = (doc.get("host_stalls") or {}).get("deadlines_missed")
    if stall is not None and not (_whole(stall) and 0 <= stall <= missed):
        return False
    if not isinstance(doc.get("host_stalls", {}), dict | type(None)):
        return False
    cov = doc.get("coverage_final")
    if cov is not None and not (_number(cov) and 0 <= cov <= 1 + 1e-9):
        return False
    detail = doc.get("status_detail")
    return detail is None or isinstance(detail, str)


def _apply(doc: dict, change: dict) -> dict:
    for name, value in change.items():
        *parents, last = FIELDS[name]
        d = doc
        for p in parents:
            d = d.setdefault(p, {}) if isinstance(d.get(p, {}), dict) else {}
        d[last] = value
    return doc


def _with_outside(base):
    """A directory outside the results, with a file that links point at."""
    outside = base / "outside"
    outside.mkdir()
    (outside / "precious").write_text("keep\n")
    return outside


@settings(SETTINGS, max_examples=120)
@given(change=changes())
@example(change={"finish": 0.0, "steps": 0})  # r2 finished at 823: out of a 0-step run
def test_a_run_report_is_correct_or_one_line(tmp_path_factory, capsys, change):
    base = tmp_path_factory.mktemp("prop")
    outside = _with_outside(base)
    run = hd.run_dir(base / "s")
    doc = _apply(json.loads((run / "result.json").read_text()), change)
    expect_ok = not any(_too_long(v) for v in change.values()) and acceptable(doc)
    (run / "result.json").write_text(json.dumps(doc))  # NaN and Infinity as Python writes them
    (run / "summary.md").symlink_to(outside / "precious")
    status, out, err = hd.within(30, hd.testbed, ["report", run], capsys)
    assert (outside / "precious").read_text() == "keep\n" and os.listdir(outside) == ["precious"]
    event("report" if status == 0 else "one line, exit 2")
    if status == 0:
        assert expect_ok, f"accepted {change}"
        assert out.startswith("# Run ")
        steps = doc.get("steps")
        shown = "–" if steps is None else str(int(steps))
        assert f"Steps run (when the last robot finished): {shown};" in out
        assert f"{doc['config']['robots']} robot(s), range {doc['config']['comm_range']:g} m" in out
        assert "\x1b" not in out
    else:
        assert status == 2 and not expect_ok, (change, err)
        lines = err.strip().splitlines()
        assert len(lines) == 1 and "result.json" in lines[0], err
    shutil.rmtree(base)


# What a file of a run directory other than result.json may be.
KINDS = ["fifo", "link out", "directory", "bytes", "json", "deep"]


RUN_FILES = [
    "medium.json", "relay-lag.bin", "aodv/r1.json", "pcaps/r1.pcap", "positions.csv",
    "display/map.npy", "routing.json", "pcaps/daemons/r1.tcpdump.log", "config.json",
]  # fmt: skip


def _make(path, kind: str, data: bytes, outside) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    elif path.exists() or path.is_symlink():
        path.unlink()
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "link out":
        path.symlink_to(outside / "precious")
    elif kind == "directory":
        path.mkdir()
    elif kind == "json":
        path.write_text(
            json.dumps(
                {
                    "robots": [{"from_linux": int.from_bytes(data[:20] or b"1")}],
                    "now_s": -len(data),
                    "messages_sent": {"RREQ": data.hex()},
                }
            )
        )
    elif kind == "deep":
        path.write_text("[" * 50_000 + "]" * 50_000)
    else:
        path.write_bytes(data)


@settings(SETTINGS, max_examples=30)
@given(
    files=st.lists(
        st.tuples(st.sampled_from(RUN_FILES), st.sampled_from(KINDS), st.binary(max_size=64)),
        min_size=1,
        max_size=3,
    ),  # fmt: skip
)
def test_any_file_of_a_run_gives_a_report_or_one_line(tmp_path_factory, capsys, files):
    base = tmp_path_factory.mktemp("prop")
    outside = _with_outside(base)
    run = hd.with_captures(hd.run_dir(base / "s"))
    for name, kind, data in files:
        _make(run / name, kind, data, outside)
    status, out, err = hd.within(30, hd.testbed, ["report", run], capsys)
    assert (outside / "precious").read_text() == "keep\n" and os.listdir(outside) == ["precious"]
    event("report" if status == 0 else "one line, exit 2")
    if status == 0:
        assert out.startswith("# Run ")
    else:
        assert status == 2, err
        assert len(err.strip().splitlines()) == 1, err
    shutil.rmtree(base)


state_values = st.one_of(
    st.none(), st.none(), st.none(), st.lists(anything, max_size=2), anything,
    st.fixed_dictionaries({"runs": st.lists(st.one_of(
        anything, st.fixed_dictionaries({"id": st.one_of(st.text(max_size=8), anything)}),
    ), max_size=3)}),
    st.fixed_dictionaries({"spec": st.one_of(anything, st.fixed_dictionaries(
        {"time_scale_by_robots": st.dictionaries(st.text(max_size=6), anything, max_size=2)}))}),
)  # fmt: skip


@settings(SETTINGS, max_examples=12)
@given(state=state_values, broken=st.lists(changes(), min_size=4, max_size=4))
# Found on Debian 12: the oracle had checked only r1's finish against a smaller `steps`.
@example(state=None, broken=[{}, {}, {"comm_range": None}, {"steps": 823, "finish": 0.0}])
def test_a_sweep_report_is_correct_or_one_line(tmp_path_factory, capsys, state, broken):
    base = tmp_path_factory.mktemp("prop")
    outside = _with_outside(base)
    sweep = hd.sweep_dir(base / "sweep")
    (sweep / "figures").mkdir()
    (sweep / "figures" / "fig2.csv").symlink_to(outside / "precious")
    bad = 0
    for run, change in zip(sorted((sweep / "runs").iterdir()), broken, strict=True):
        doc = _apply(json.loads((run / "result.json").read_text()), change)
        bad += not acceptable(doc) or any(_too_long(v) for v in change.values())
        (run / "result.json").write_text(json.dumps(doc))
    if state is not None:
        (sweep / "sweep.json").write_text(json.dumps(state))
    status, _, err = hd.within(60, hd.testbed, ["report", sweep], capsys)
    assert (outside / "precious").read_text() == "keep\n" and os.listdir(outside) == ["precious"]
    event("report" if status == 0 else "one line, exit 2")
    event(f"{bad} of 4 runs left out")
    if status == 0:
        md = (sweep / "report.md").read_text()
        assert (f"**Left out: {bad} run(s)" in md) == (bad > 0), md[:600]
        assert "NaN" not in (sweep / "figures" / "fig2.csv").read_text()
    else:
        assert status == 2, err
        (line,) = err.strip().splitlines()
        assert "sweep.json" in line
    shutil.rmtree(base)
