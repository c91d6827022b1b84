"""The event log's type (node.events): what EventLog writes reads back the same, the event's
name is read from a line's first bytes without parsing it, and what is not an event (a line
cut short, not an object, a FIFO for a log) is skipped or refused."""

import json
import os

import pytest

from common import boundedfile
from node import events
from node.events import Event, EventLog


def _log(path, *recs):
    log = EventLog(str(path))
    for name, step, fields in recs:
        log.write(name, step, **fields)
    log.close()


def test_what_the_log_writes_reads_back_byte_for_byte(tmp_path):
    path = tmp_path / "r1.events.jsonl"
    plan = ("plan", 3, {"cause": "start", "goal": [1.5, 2.0], "ms": 0.4})
    _log(path, plan, ("send", 4, {"kind": "map", "seq": 1}), ("summary", 9, {"x": None}))
    lines = path.read_text().splitlines()
    assert lines[0] == '{"e":"plan","step":3,"cause":"start","goal":[1.5,2.0],"ms":0.4}'
    evs = events.read(path)
    assert [e.to_line() for e in evs] == lines
    assert evs[0] == Event("plan", 3, {"cause": "start", "goal": [1.5, 2.0], "ms": 0.4})
    assert evs[0].get("goal") == [1.5, 2.0] and evs[0].get("e") == "plan"
    assert evs[2].get("step") == 9 and evs[2].get("nothing", 7) == 7
    assert evs[2].to_dict() == json.loads(lines[2])


def test_only_the_events_asked_for_are_parsed(tmp_path, monkeypatch):
    path = tmp_path / "r1.events.jsonl"
    _log(path, *[("send", i, {"kind": "map"}) for i in range(5)], ("plan", 5, {"cause": "c"}))
    parsed = []
    real = events.parse
    monkeypatch.setattr(events, "parse", lambda line: parsed.append(line) or real(line))
    assert [e.e for e in events.read(path, only=("plan",))] == ["plan"]
    assert len(parsed) == 1


@pytest.mark.parametrize(
    ("line", "name"),
    [
        (b'{"e":"send","step":1}', "send"),
        ('{"e":"plan","step":1}', "plan"),
        (b'{"step": 1, "e": "recv"}', "recv"),  # not the writers' order: parsed
        (b'{"e":"se\\u006ed","step":1}', "send"),  # an escape in the name: parsed
        (b'{"e":"send","st', None),  # cut short: the prefix alone does not make an event
        (b"[1, 2]", None),
    ],
)
def test_event_name(line, name):
    got = events.event_name(line)
    if name is None and line.startswith(b'{"e":"'):
        assert events.parse(line) is None  # the reader skips it all the same
    else:
        assert got == name


@pytest.mark.parametrize(
    "line",
    ['{"e":"send","step":1', "[]", '"x"', '{"step":1}', '{"e":1,"step":1}',
     '{"e":"send","step":"1"}', '{"e":"send","step":true}', '{"e":"send"}', "\xff", ""],
)  # fmt: skip
def test_a_line_that_is_no_event_is_skipped(line):
    assert events.parse(line) is None
    assert list(events.parse_lines([line, '{"e":"x","step":2}'])) == [Event("x", 2, {})]


def test_a_bad_byte_spoils_its_line_only(tmp_path):
    path = tmp_path / "log"
    path.write_bytes(b'{"e":"a","step":1}\n{"e":"\xff","step":2}\n{"e":"b","step":3}\n\xff\n')
    assert [e.e for e in events.read(path)] == ["a", "\ufffd", "b"]
    assert [e.e for e in events.read(path, only=("b",))] == ["b"]


def test_a_line_longer_than_max_line_is_skipped(tmp_path, monkeypatch):
    monkeypatch.setattr(events, "MAX_LINE", 40)
    path = tmp_path / "log"
    path.write_text('{"e":"a","step":1}\n{"e":"b","step":2,"x":"' + "y" * 40 + '"}\n')
    assert [e.e for e in events.read(path)] == ["a"]
    assert events.read(path, only=("b",)) == []


def test_a_missing_log_is_empty_and_a_fifo_is_refused(tmp_path):
    assert events.read(tmp_path / "none") == []
    os.mkfifo(tmp_path / "fifo")
    with pytest.raises(boundedfile.Refused) as r:
        events.read(tmp_path / "fifo")
    assert r.value.kind == "special"
    with pytest.raises(boundedfile.Refused):
        events.read(tmp_path)


def test_the_line_prefix_is_how_the_writers_start_a_line(tmp_path):
    path = tmp_path / "r1.events.jsonl"
    _log(path, ("send", 1, {"kind": "map"}), ("sender", 2, {}), ("plan", 3, {"goal": [1, 2]}))
    lines = path.read_bytes().splitlines()
    send = events.line_prefix("send")
    assert [ln.startswith(send) for ln in lines] == [True, False, False]  # not "sender"
    assert [events.event_name(ln) for ln in lines] == ["send", "sender", "plan"]
    # the C++ robot's lines start the same way (native/robot/events.h)
    assert b'{"e":"plan","step":3,"goal":[1,2]}'.startswith(events.line_prefix("plan"))
