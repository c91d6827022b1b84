"""An AODV daemon's statistics file as one type (aodv.statsfile.DaemonStats): what the daemon
writes is the bytes it wrote before the type and reads back the same, old files get their
defaults, and a malformed file is one line naming the file and the key."""

import json
import os
import time

import pytest

from aodv.stats import Stats
from aodv.statsfile import DaemonStats, StatsError, run_stats_files, run_stats_path

# What the daemon wrote (aodv/stats.py, before the type) for the counters `_stats` sets.
WRITTEN = {
    "addr": "10.0.0.1",
    "bytes_not_transmitted": 20,
    "bytes_received": 120,
    "bytes_sent": 300,
    "cpu_s": 2.25,
    "discoveries": [
        {
            "dest": "10.0.0.3",
            "latency_s": 0.012345,
            "ok": True,
            "round_latency_s": 0.01,
            "t": 999.1,
        },
        {"dest": "10.0.0.4", "latency_s": 2.5, "ok": False, "round_latency_s": 1.0, "t": 999.9},
    ],
    "discoveries_failed": 1,
    "discoveries_ok": 1,
    "dropped": {"malformed": 1},
    "icmp_unreachable_sent": 1,
    "local_repairs": {"ok": 1},
    "messages_not_transmitted": {"RREP": 1},
    "messages_received": {"RREP": 2},
    "messages_sent": {"HELLO": 10, "RREQ": 3},
    "packets_buffered": 2,
    "packets_released": 2,
    "pid": 4242,
    "protocol_dropped": {"rreq_rate": 5},
    "robot": "r1",
    "route_deletes": 1,
    "route_installs": 4,
    "route_use_refreshes": 7,
    "routes": {"10.0.0.3": {"hops": 2, "next_hop": "10.0.0.2"}},
    "timer_lateness_ms": {
        "expiry": {
            "hist": {"<=10": 0, "<=100": 0, "<=200": 0, "<=25": 0, "<=50": 0, ">200": 1},
            "late": 1,
            "max": 300.0,
            "n": 1,
            "worst": [[102.0, 102.3, 300.0]],
        },
        "hello": {
            "hist": {"<=10": 1, "<=100": 0, "<=200": 0, "<=25": 1, "<=50": 0, ">200": 0},
            "late": 1,
            "max": 12.5,
            "n": 2,
            "worst": [[100.0, 100.01, 12.5], [101.0, 101.0, 0.0]],
        },
    },
    "uptime_s": 0.0,
}


def _stats(monkeypatch) -> Stats:
    monkeypatch.setattr(time, "time", lambda: 1000.5)
    monkeypatch.setattr(time, "process_time", lambda: 2.25)
    monkeypatch.setattr(os, "getpid", lambda: 4242)
    s = Stats("r1", "10.0.0.1")
    s.sent.update({"RREQ": 3, "HELLO": 10})
    s.received.update({"RREP": 2})
    s.bytes_sent, s.bytes_received = 300, 120
    s.dropped.update({"malformed": 1})
    s.not_transmitted.update({"RREP": 1})
    s.bytes_not_transmitted = 20
    s.route_installs, s.route_deletes, s.packets_buffered, s.packets_released = 4, 1, 2, 2
    s.icmp_unreachable, s.route_uses = 1, 7
    s.discoveries = [
        {"dest": "10.0.0.3", "ok": True, "latency_s": 0.012345, "round_latency_s": 0.01,
         "t": 999.1},
        {"dest": "10.0.0.4", "ok": False, "latency_s": 2.5, "round_latency_s": 1.0, "t": 999.9},
    ]  # fmt: skip
    s.local_repairs.update({"ok": 1})
    s.protocol_dropped.update({"rreq_rate": 5})
    s.routes = {"10.0.0.3": {"next_hop": "10.0.0.2", "hops": 2}}
    s.timer_lateness["hello"].add(12.5, 100.0, 100.01)
    s.timer_lateness["hello"].add(0.0, 101.0, 101.0)
    s.timer_lateness["expiry"].add(300.0, 102.0, 102.3)
    return s


def test_what_the_daemon_writes_is_the_old_bytes_and_reads_back_the_same(tmp_path, monkeypatch):
    stats = _stats(monkeypatch)
    path = tmp_path / "r1.aodv.json"
    stats.write(str(path))
    assert path.read_text() == json.dumps(WRITTEN, indent=1, sort_keys=True) + "\n"
    read = DaemonStats.read(path)
    assert read == stats.snapshot()
    assert read.to_json() == WRITTEN


def test_the_rewrites_while_the_daemon_runs_are_one_line_of_the_same_content(tmp_path, monkeypatch):
    """The daemon's rewrites every STATS_PERIOD go through json's compiled encoder (one line);
    what they hold is what the indented file holds, from the daemon's snapshot and from a
    file read back (read-only mappings)."""
    stats = _stats(monkeypatch)
    path = tmp_path / "r1.aodv.json"
    stats.write(str(path), compact=True)
    text = path.read_text()
    assert text.count("\n") == 1 and text.endswith("\n")
    assert json.loads(text) == WRITTEN
    assert DaemonStats.read(path) == stats.snapshot()
    DaemonStats.read(path).write(path, compact=True)
    assert path.read_text() == text


def test_the_fields_readers_use():
    s = DaemonStats.from_json(WRITTEN)
    assert s.sent_total == 13 and s.messages_not_transmitted == {"RREP": 1}
    assert s.bytes_sent - s.bytes_not_transmitted == 280
    assert s.discovery_latencies_s == [0.012345]
    assert s.timer_lateness_ms is not None and s.timer_lateness_ms["expiry"]["max"] == 300.0
    assert s.discoveries[0]["dest"] == "10.0.0.3" and s.routes["10.0.0.3"]["hops"] == 2


def test_an_old_file_gets_its_defaults():
    """The first daemons wrote neither what the kernel reported unsent, nor the core's drops
    or local repairs, nor timer lateness or CPU time."""
    old = {k: v for k, v in WRITTEN.items() if k not in (
        "messages_not_transmitted", "bytes_not_transmitted", "protocol_dropped",
        "local_repairs", "timer_lateness_ms", "cpu_s")}  # fmt: skip
    s = DaemonStats.from_json(old)
    assert s.messages_not_transmitted == {} and s.bytes_not_transmitted == 0
    assert s.protocol_dropped == {} and s.local_repairs == {}
    assert s.timer_lateness_ms is None and s.cpu_s is None
    bare = DaemonStats.from_json({"messages_sent": {"RREQ": 1}})
    assert (bare.robot, bare.pid, bare.discoveries, bare.routes) == (None, None, (), {})


def test_a_run_keeps_them_as_aodv_rk_json(tmp_path):
    assert run_stats_files(tmp_path) is None
    (tmp_path / "aodv").mkdir()
    assert run_stats_files(tmp_path) == []
    for k in (2, 1):
        DaemonStats.from_json(WRITTEN).write(run_stats_path(tmp_path, k))
    assert run_stats_files(tmp_path) == [
        tmp_path / "aodv" / "r1.json",
        tmp_path / "aodv" / "r2.json",
    ]


def _with(**change):
    return dict(WRITTEN, **change)


@pytest.mark.parametrize(
    ("doc", "key"),
    [
        ([], "not a JSON object"),
        ({"robot": "r1"}, "messages_sent"),
        (_with(messages_sent={"RREQ": -3}), "messages_sent.RREQ"),
        (_with(messages_sent={"RREQ": 1.5}), "messages_sent.RREQ"),
        (_with(messages_sent={"RR\nEQ": True}), "messages_sent.RR?EQ"),
        (_with(messages_not_transmitted=[]), "messages_not_transmitted"),
        (_with(bytes_sent="9" * 5000), "bytes_sent"),
        (_with(bytes_sent=10**16), "bytes_sent"),
        (_with(robot=1), "robot"),
        (_with(pid=1.5), "pid"),
        (_with(cpu_s="2"), "cpu_s"),
        (_with(routes={"a": 1}), "routes"),
        (_with(discoveries={}), "discoveries"),
        (_with(discoveries=[1]), "discoveries[0]"),
        (_with(discoveries=[{"ok": 1}]), "discoveries[0].ok"),
        (_with(discoveries=[{"ok": True}]), "discoveries[0]"),
        (_with(discoveries=[{"ok": True, "latency_s": "1"}]), "discoveries[0].latency_s"),
        (_with(timer_lateness_ms={"hello": 1}), "timer_lateness_ms"),
        (_with(timer_lateness_ms={"hello": {"max": "x"}}), "timer_lateness_ms.hello.max"),
        (_with(timer_lateness_ms={"hello": {"n": -1}}), "timer_lateness_ms.hello.n"),
        (_with(timer_lateness_ms={"hello": {"worst": [[1, 2]]}}), "timer_lateness_ms.hello.worst"),
    ],
)
def test_a_malformed_file_is_one_line_naming_the_key(tmp_path, doc, key):
    with pytest.raises(StatsError) as e:
        DaemonStats.from_json(doc)
    assert key in str(e.value)
    path = tmp_path / "r1.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(StatsError) as r:
        DaemonStats.read(path)
    said = str(r.value)
    assert said.startswith(f"{path}: ") and key in said and "\n" not in said


def test_a_file_that_is_not_one_is_one_line(tmp_path):
    with pytest.raises(StatsError, match="no such file"):
        DaemonStats.read(tmp_path / "none.json")
    (tmp_path / "r1.json").write_text('{"messages_sent": ')
    with pytest.raises(StatsError, match="r1.json: unreadable: not valid JSON"):
        DaemonStats.read(tmp_path / "r1.json")
    os.mkfifo(tmp_path / "fifo.json")
    with pytest.raises(StatsError, match="not a regular file"):
        DaemonStats.read(tmp_path / "fifo.json")


def test_the_run_reads_its_daemons_through_the_type(tmp_path):
    """testbed.run.results: the fidelity verdict's timer lateness and the routing CPU seconds
    come from the daemons whose file is one; a malformed one is left out like a missing one."""
    from testbed.run.results import daemon_stats

    (tmp_path / "aodv").mkdir()
    DaemonStats.from_json(WRITTEN).write(run_stats_path(tmp_path, 1))
    run_stats_path(tmp_path, 2).write_text('{"messages_sent": {"RREQ": -1}}')
    (daemon,) = daemon_stats(str(tmp_path), 3)
    assert daemon.robot == "r1" and daemon.cpu_s == 2.25 and daemon.timer_lateness_ms
