"""Issue 40, items 4 and 5: files of a results directory that used to end in a traceback or
in a silently wrong report. Each case is one line and exit 2 naming the file and the field
(a run's own report), or the run left out and named (a sweep's report), or the part that
cannot be read left out and said (captures, counters, the paths picture); never a traceback
and never a verdict drawn from impossible numbers."""

import json
import os

import numpy as np
import pytest

from testbed.analysis import capturefiles, pathsfig, pcapmetrics
from testbed.analysis.runs import load_runs
from tests.unit import hostile_dirs as hd


def _set(path: str, value):
    def change(doc):
        *parents, last = path.split(".")
        for p in parents:
            doc = doc[p]
        doc[last] = value

    return change


# (case, how result.json is changed, the field the refusal names)
BAD_RESULTS = [
    ("steps 10.5", _set("steps", 10.5), "'steps'"),
    ("steps -100", _set("steps", -100), "'steps'"),
    ("robots 0", _set("config.robots", 0), "config.robots"),
    ("robots -3", _set("config.robots", -3), "config.robots"),
    ("range 0", _set("config.comm_range", 0), "config.comm_range"),
    ("finish beyond the run", _set("robots.r1.finish_step", 5000), "finish_step"),
    ("finish negative", _set("robots.r1.finish_step", -1), "finish_step"),
    ("plan at step -4", _set("robots.r1.plans", [{"step": -4}]), "plans.step"),
    ("plan at step 1.5", _set("robots.r1.plans", [{"step": 1.5}]), "plans.step"),
    ("deadlines missed -5", _set("deadlines_missed", -5), "deadlines_missed"),
    ("stall misses above all", _set("host_stalls", {"deadlines_missed": 5}), "host_stalls"),
    ("miss fraction 2", _set("deadline_miss_fraction", 2.0), "deadline_miss_fraction"),
    ("coverage 3", _set("coverage_final", 3.0), "coverage_final"),
    ("time scale -1", _set("time_scale_achieved", -1.0), "time_scale_achieved"),
    ("time scale asked 0", _set("time_scale_requested", 0), "time_scale_requested"),
    ("mean beyond the run", _set("mean_finish_step", 1e9), "mean_finish_step"),
    ("cause a number", _set("robots.r1.plans", [{"step": 1, "cause": 5}]), "cause"),
    ("a count -1", _set("robots.r1.messages", {"sent": {"goal": -1}}), "messages.sent"),
]
# Text no JSON encoder writes: the strict reader refuses it (common.boundedfile).
BAD_TEXTS = [
    ("NaN steps", '"steps": 823', '"steps": NaN', "NaN"),
    ("Infinity steps", '"steps": 823', '"steps": Infinity', "Infinity"),
    ("1e400 steps", '"steps": 823', '"steps": 1e400', "finite"),
    ("finish 10**400", '"finish_step": 817', '"finish_step": 1' + "0" * 400, "401 digits"),
    ("plan at Infinity", '"step": 0', '"step": Infinity', "Infinity"),
]


@pytest.mark.parametrize(("case", "change", "field"), BAD_RESULTS, ids=[c[0] for c in BAD_RESULTS])
def test_impossible_values_are_one_line_naming_the_field(tmp_path, capsys, case, change, field):
    run = hd.run_dir(tmp_path / "s")
    hd.edit_result(run, change)
    hd.refused(["report", run], capsys, "result.json", field)


@pytest.mark.parametrize(("case", "old", "new", "says"), BAD_TEXTS, ids=[c[0] for c in BAD_TEXTS])
def test_numbers_json_does_not_allow_are_one_line(tmp_path, capsys, case, old, new, says):
    run = hd.run_dir(tmp_path / "s")
    text = (run / "result.json").read_text()
    assert old in text
    (run / "result.json").write_text(text.replace(old, new, 1))
    hd.refused(["report", run], capsys, "result.json", says)


@pytest.mark.parametrize("name", ["result.json", "medium.json"])
def test_deep_nesting_is_one_line_not_a_recursion_error(tmp_path, capsys, name):
    run = hd.run_dir(tmp_path / "s")
    (run / name).write_text("[" * 100_000 + "]" * 100_000)
    hd.refused(["report", run], capsys, name, "nested deeper")


def test_a_sweep_draws_no_verdict_from_negative_steps(tmp_path, capsys):
    sweep = hd.sweep_dir(tmp_path / "sweep")
    for run in (sweep / "runs").iterdir():
        hd.edit_result(run, lambda d: [r.update(finish_step=-20) for r in d["robots"].values()])
    status, _, err = hd.testbed(["report", sweep], capsys)
    assert status == 0, err
    md = (sweep / "report.md").read_text()
    assert "**Left out: 4 run(s)" in md and "finish_step" in md
    assert "Team work beats one robot | **holds**" not in md
    assert load_runs(sweep) == []


def test_compare_draws_nothing_from_negative_steps(tmp_path, capsys):
    a, b = hd.sweep_dir(tmp_path / "a"), hd.sweep_dir(tmp_path / "b")
    for run in (a / "runs").iterdir():
        hd.edit_result(run, _set("steps", -10))
    status, out, err = hd.testbed(["compare", a, b], capsys)
    assert status == 0, err
    assert "within the noise" not in out


# -- sweep.json: type-checked (testbed.files.sweepstate) ------------------------------------------

BAD_STATES = [
    ("a list", []),
    ("spec a list", {"spec": [], "runs": []}),
    ("runs an object", {"runs": {}}),
    ("a run without id", {"runs": [{"status": "done"}]}),
    ("an int id", {"runs": [{"id": 3}]}),
    ("an id with a slash", {"runs": [{"id": "../../etc"}]}),
    ("a string time scale", {"spec": {"time_scale_by_robots": {"2": "fast"}}}),
    ("a 5000-digit team", {"spec": {"time_scale_by_robots": {"9" * 5000: 1}}}),
    ("a string factor", {"time_scale_factor": {"2": "x"}}),
    ("a status number", {"runs": [{"id": "a", "status": 3}]}),
]


@pytest.mark.parametrize(("case", "doc"), BAD_STATES, ids=[c[0] for c in BAD_STATES])
def test_a_malformed_sweep_json_is_one_line_for_report_and_status(tmp_path, capsys, case, doc):
    sweep = hd.sweep_dir(tmp_path / "sweep")
    (sweep / "sweep.json").write_text(json.dumps(doc))
    hd.refused(["report", sweep], capsys, "sweep.json")
    hd.refused(["sweep", "--status", sweep], capsys, "sweep.json")


def test_a_sweep_whose_name_is_not_utf8_is_reported(tmp_path, capsys):
    sweep = hd.sweep_dir(tmp_path / os.fsdecode(b"sw\xff\x1b[2J"))
    status, _, err = hd.testbed(["report", sweep], capsys)
    assert status == 0, err
    md = (sweep / "report.md").read_text()
    assert md.startswith("# Sweep report: sw\\udcff\\x1b[2J")
    assert "\x1b" not in err and "\x1b" not in md


# -- the paths picture -----------------------------------------------------------------------


def _paths_run(tmp_path):
    sweep = hd.sweep_dir(tmp_path / "sweep")
    run = sorted((sweep / "runs").iterdir())[0]
    (run / "positions.csv").write_text("step,x1,y1\n0,1,1\n1,2,2\n")
    return sweep, run


def _npy_header(shape, descr="|u1") -> bytes:
    head = f"{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}"
    head = head.ljust(117) + "\n"
    return b"\x93NUMPY\x01\x00" + len(head).to_bytes(2, "little") + head.encode()


BAD_PATHS = [
    ("a header that is not step,xK,yK", "positions.csv", b"step,a,b\n0,1,1\n"),
    ("a robot 10**30", "positions.csv", b"step,x" + b"9" * 30 + b",y" + b"9" * 30 + b"\n0,1,1\n"),
    ("a coordinate 1e400", "positions.csv", b"step,x1,y1\n0,1e400,1\n"),
    ("a 4-D map", "display/map.npy", _npy_header((2, 2, 2, 2)) + bytes(16)),
    ("a map of 10**12 cells", "display/map.npy", _npy_header((1000000, 1000000))),
    ("a map of floats", "display/map.npy", _npy_header((2, 2), "<f8") + bytes(32)),
]


@pytest.mark.parametrize(("case", "name", "data"), BAD_PATHS, ids=[c[0] for c in BAD_PATHS])
def test_a_bad_positions_or_map_file_leaves_the_picture_out(tmp_path, capsys, case, name, data):
    sweep, run = _paths_run(tmp_path)
    (run / name).parent.mkdir(exist_ok=True)
    (run / name).write_bytes(data)
    status, _, err = hd.testbed(["report", sweep], capsys)
    assert status == 0, err
    with pytest.raises(pathsfig.PathsError):
        pathsfig.write_paths(load_runs(sweep)[0], tmp_path / "p")
    assert not (sweep / "figures" / "paths" / f"{run.name}.png").exists()


@pytest.mark.parametrize(
    ("key", "value"), [("map_size", [0, 0]), ("map_cell", -0.05), ("map_cell", "5")]
)
def test_a_bad_map_size_or_cell_leaves_the_picture_out(tmp_path, key, value):
    sweep, run = _paths_run(tmp_path)
    hd.edit_result(run, lambda d: d["config"].setdefault("extra", {}).update({key: value}))
    with pytest.raises(pathsfig.PathsError, match=key):
        pathsfig.write_paths(load_runs(sweep)[0], tmp_path / "p")


def test_a_good_map_is_still_drawn(tmp_path):
    sweep, run = _paths_run(tmp_path)
    (run / "display").mkdir()
    np.save(run / "display" / "map.npy", np.ones((40, 40), dtype=np.uint8))
    assert pathsfig.write_paths(load_runs(sweep)[0], tmp_path / "p").is_file()


# -- captures, the daemons' counters and the routing cache -----------------------------------


@pytest.mark.parametrize("name", ["r0.pcap", "r5000.pcap", "r" + "9" * 30 + ".pcap", "rx.pcap"])
def test_a_capture_not_named_for_a_robot_is_left_out_and_named(tmp_path, name):
    run = hd.with_captures(hd.run_dir(tmp_path / "s"))
    (run / "pcaps" / name).write_bytes(hd.EMPTY_PCAP)
    found = capturefiles.find(run)
    assert sorted(found.paths) == [1, 2]
    assert name[:80] in found.left_out


def test_an_empty_capture_credits_no_frames_to_another_robot(tmp_path):
    """mergecap skips a 0-byte capture: r2's frames used to come back as r1's."""
    run = hd.run_dir(tmp_path / "s")
    (run / "pcaps").mkdir()
    (run / "pcaps" / "r1.pcap").write_bytes(b"")
    (run / "pcaps" / "r2.pcap").write_bytes(hd.udp_pcap(2, 5))
    (run / "pcaps" / "r3.pcap").write_bytes(hd.udp_pcap(3, 2))
    found = capturefiles.find(run)
    assert found.left_out == {"r1.pcap": "empty or cut short (no capture header)"}
    frames = pcapmetrics.read_pcaps(found.paths)
    assert {k: len(v) for k, v in frames.items()} == {2: 5, 3: 2}
    assert all(f.ip_src == "10.0.0.2" for f in frames[2])


def test_a_missing_capture_is_named_in_the_summary(tmp_path, capsys):
    run = hd.run_dir(tmp_path / "s")
    (run / "pcaps").mkdir()
    (run / "pcaps" / "r2.pcap").write_bytes(hd.udp_pcap(2, 3))
    status, out, err = hd.testbed(["report", run], capsys)
    assert status == 0, err
    assert "**Captures left out**" in out and "r1.pcap (missing)" in out


@pytest.mark.parametrize(
    "doc",
    [
        {"messages_sent": {"RREQ": 1e400}},
        {"messages_sent": {"RREQ": -3}},
        {"messages_sent": {"RREQ": 1}, "bytes_sent": "9" * 5000},
        {"messages_sent": {"RREQ": 1.5}},
        "deep",
    ],
    ids=["1e400", "negative", "5000-digit string", "fraction", "deep"],
)
def test_impossible_daemon_counters_are_left_out(tmp_path, doc):
    run = hd.with_captures(hd.run_dir(tmp_path / "s"))
    text = "[" * 100_000 + "]" * 100_000 if doc == "deep" else json.dumps(doc)
    text = text.replace("Infinity", "1e400")  # json.dumps writes 1e400 as Infinity
    (run / "aodv" / "r1.json").write_text(text)
    counts = capturefiles.daemon_counts(run)
    assert set(counts) == {"r2"}


def test_a_5000_digit_drop_count_is_not_read_by_its_tail(tmp_path):
    run = hd.with_captures(hd.run_dir(tmp_path / "s"))
    (run / "pcaps" / "daemons" / "r1.tcpdump.log").write_text(
        "9" * 5000 + " packets dropped by kernel\n"
    )
    assert capturefiles.capture_drops(run) == {"r2": 0}


def test_a_shipped_routing_cache_is_checked_not_trusted(tmp_path):
    """tar keeps mtimes: a cache keyed on size and mtime was taken whatever it said."""
    run = hd.run_dir(tmp_path / "s")
    (run / "pcaps").mkdir()
    for k in (1, 2):
        (run / "pcaps" / f"r{k}.pcap").write_bytes(hd.udp_pcap(k, 3))
    first = pcapmetrics.run_metrics(run)
    doc = json.loads((run / "routing.json").read_text())
    doc.update(pdf=7.5, delay_ms_median=-1e9)  # the captures' own stamp kept
    (run / "routing.json").write_text(json.dumps(doc))
    assert pcapmetrics.run_metrics(run).pdf == first.pdf
    other = dict(doc, pdf=0.5)  # plausible, but for other captures: their hashes differ
    other["pcaps"] = {name: "0" * 64 for name in doc["pcaps"]}
    (run / "routing.json").write_text(json.dumps(other))
    assert pcapmetrics.run_metrics(run).pdf == first.pdf


def test_a_capture_linked_out_of_the_run_is_left_out(tmp_path):
    run = hd.run_dir(tmp_path / "s")
    (run / "pcaps").mkdir()
    secret = tmp_path / "secret"
    secret.write_bytes(hd.udp_pcap(1, 2))
    (run / "pcaps" / "r1.pcap").symlink_to(secret)
    (run / "pcaps" / "r2.pcap").write_bytes(hd.udp_pcap(2, 2))
    found = capturefiles.find(run)
    assert sorted(found.paths) == [2] and "link out" in found.left_out["r1.pcap"]


def test_a_nan_in_a_figures_table_is_left_empty_and_said(tmp_path, caplog):
    from testbed.analysis import tables
    from testbed.analysis.rows import MeanRange

    nan = MeanRange(float("nan"), 1.0, 2.0)
    rows = [tables.ImpairmentRow(2, 5.0, 0.0, 0.0, 1, nan, MeanRange())]
    tables.write_table(rows, tmp_path / "fig2")
    assert (tmp_path / "fig2.csv").read_text().splitlines()[1] == "2,5.0,0.0,0.0,1,,1.0,2.0,,,"
    assert json.loads((tmp_path / "fig2.json").read_text())[0]["steps_mean"] is None
    assert "steps_mean" in caplog.text and "not a number" in caplog.text


@pytest.mark.parametrize(
    "config",
    [
        {"robots": "2"},
        {"robots": 2, "laser_rays": 10**8},
        {"nonsense": 1},
        {"robots": 2, "kill": ["r1:99999999999999999"]},
        {"robots": 2, "snapshots": "x"},
    ],  # fmt: skip
    ids=["string robots", "a laser of 10**8 rays", "an unknown key", "a huge kill", "snapshots"],
)
def test_a_runs_config_in_sweep_json_is_checked(tmp_path, capsys, config):
    sweep = hd.sweep_dir(tmp_path / "sweep")
    (sweep / "sweep.json").write_text(json.dumps({"runs": [{"id": "a", "config": config}]}))
    hd.refused(["sweep", "--status", sweep], capsys, "sweep.json", "runs[0].config")


def test_a_run_that_never_stepped_is_still_read(tmp_path, capsys):
    """A run that failed before its first step writes steps 0 and an achieved scale of 0:
    a real result, counted as failed, not refused as impossible."""
    run = hd.run_dir(tmp_path / "s")

    def failed(doc):
        doc.update(status="failed", steps=0, time_scale_achieved=0.0, coverage_final=0.0)
        for r in doc["robots"].values():
            r.update(finish_step=None, plans=[])

    hd.edit_result(run, failed)
    status, out, err = hd.testbed(["report", run], capsys)
    assert status == 0, err
    assert "Status **failed**" in out


def test_a_plan_at_step_infinity_neither_breaks_the_view_nor_a_resume(tmp_path, capsys):
    from testbed.sweep.rundir import is_done
    from testbed.view import replay

    sweep = hd.sweep_dir(tmp_path / "sweep")
    run = sorted((sweep / "runs").iterdir())[0]
    text = (run / "result.json").read_text()
    (run / "result.json").write_text(text.replace('"step": 0', '"step": Infinity', 1))
    (run / "positions.csv").write_text("step,x1,y1\n0,1,1\n")
    assert replay.load(run)["status"] == "unknown"  # the result unreadable, the replay drawn
    assert is_done(sweep, run.name)  # a finished run whose result says nothing: not redone
    status, _, err = hd.testbed(["report", sweep], capsys)
    assert status == 0 and "**Left out: 1 run(s)" in (sweep / "report.md").read_text(), err
