"""A robot's event log as one type: `EventLog` writes it, `Event` is one of its lines, and
`read` / `parse_lines` are the one way back in, for the run to summarise and check.

Every record has "e" (the event) and "step" (the robot's step when it happened), then the
event's own fields ("kind", "goal", "frm", ...). Each line is written whole, at once, so a
robot killed mid-run leaves every complete line behind. The C++ robot (native/robot/events.h)
writes the same lines, compact JSON with "e" first, so `event_name` (and, cheaper,
`line_prefix`) can tell a line's event from its first bytes without parsing it: a reader that
wants only some events (the live view counts sends every second) parses only those lines.

Reading: a line cut short by a crash, one that is not a JSON object, or one without a string
"e" and a whole-number "step" is skipped (a log is evidence, not input to trust), and so
is a line longer than MAX_LINE; a byte that is not UTF-8 (only in a damaged log) reads as
U+FFFD; a missing log is empty; anything but a regular file of at most MAX_LOG_BYTES is
refused (common.boundedfile.Refused). Values keep the type JSON gave them. Nobody else
opens an event log to parse its lines (tests/unit/test_file_types.py holds this).
"""

from __future__ import annotations

import errno
import io
import json
import logging
import os
import threading
from collections.abc import Collection, Iterable, Iterator, Mapping
from types import MappingProxyType
from typing import Any, NamedTuple, cast

from common import boundedfile

log = logging.getLogger(__name__)

EVENTS_SUFFIX = ".events.jsonl"  # robots/rK.events.jsonl; the display's: display/events.jsonl
MAX_LINE = 1 << 20  # a map diff or a summary is a few kB
MAX_LOG_BYTES = 1 << 30  # a day-long run of one robot logs well under a GB
_PREFIX = b'{"e":"'  # how every line starts (json.dumps with compact separators, and C++)
_NO_FIELDS: Mapping[str, Any] = MappingProxyType({})


class EventLog:
    """Writes a log: each line one write(2) under a lock, so that a robot killed mid-run
    leaves complete lines. A write that fails (a full disk) loses its event: the log counts
    it (`failed`, the summary's "events_failed"), says so once in the process's log, and
    starts its next line on a line of its own when the failed one was cut short; the C++
    robot's (native/robot/events.cc) does the same."""

    def __init__(self, path: str | None):
        # As open(path, "a"): created 0666 less the umask, appended to, closed on exec, and
        # at its end (a file that cannot seek there, /proc/self/mem say, is refused: OSError).
        flags = os.O_WRONLY | os.O_CREAT | os.O_APPEND | os.O_CLOEXEC
        self.fd: int | None = os.open(path, flags, 0o666) if path else None
        if self.fd is not None:
            try:
                os.lseek(self.fd, 0, os.SEEK_END)
            except OSError:
                os.close(self.fd)
                raise
        self.path = path
        self.lock = threading.Lock()
        self.failed = 0  # events lost to a failed write
        self._cut = False  # a failed write left part of a line in the file

    def write(self, event: str, step: int, **fields) -> None:
        if self.fd is None:
            return
        data = (Event(event, step, fields).to_line() + "\n").encode()
        with self.lock:
            if self.fd is None:
                return
            if self._cut:
                data = b"\n" + data
            done = 0
            try:
                while done < len(data):
                    n = os.write(self.fd, data[done:])
                    if n == 0:  # never for a file, but no spinning under the lock
                        raise OSError(errno.EIO, "nothing written")
                    done += n
            except OSError as e:
                self._cut = self._cut or done > 0
                self.failed += 1
                if self.failed == 1:
                    log.warning(
                        "cannot write the event log %s: %s; events are lost (counted in the "
                        "summary's events_failed)", self.path, e.strerror or e,
                    )  # fmt: skip
                return
            self._cut = False

    def close(self) -> None:
        with self.lock:
            if self.fd is not None:
                os.close(self.fd)
                self.fd = None


class Event(NamedTuple):
    """One line of an event log: the event `e`, the robot's `step`, and the event's other
    fields in the order they were written (a tuple: a log of a long run holds millions)."""

    e: str
    step: int
    fields: Mapping[str, Any] = _NO_FIELDS

    def get(self, name: str, default: Any = None) -> Any:
        """Field `name` ("e" and "step" too), `default` where the line has none."""
        if name == "e":
            return self.e
        if name == "step":
            return self.step
        return self.fields.get(name, default)

    def to_dict(self) -> dict[str, Any]:
        """The line's object, keys in the file's order."""
        return {"e": self.e, "step": self.step, **self.fields}

    def to_line(self) -> str:
        """The line the writers write (without its newline)."""
        return json.dumps(self.to_dict(), separators=(",", ":"))

    @classmethod
    def from_dict(cls, d: Any) -> Event | None:
        """The event an object holds; None unless it has a string "e" and a whole "step"."""
        if not isinstance(d, dict):
            return None
        return _event(dict(d))


def _event(d: dict) -> Event | None:
    """from_dict of an object of the reader's own (its "e" and "step" taken out of it)."""
    e, step = d.pop("e", None), d.pop("step", None)
    if e.__class__ is not str or step.__class__ is not int:  # not a subclass: no bool
        return None
    return Event(e, step, d)


def line_prefix(name: str) -> bytes:
    """How the writers start a line of event `name` (compact JSON, "e" first): what a reader
    that only counts or picks some events tells a line by, many times a second, without
    parsing it (a tenth of event_name's cost). Lines others wrote in another order do not
    match; `event_name` reads those too."""
    return _PREFIX + json.dumps(name).encode()[1:]


def event_name(line: bytes | str) -> str | None:
    """The event a line holds, read from its first bytes where it starts as the writers
    start it; otherwise (or when the name has an escape) from the whole line parsed. None for
    a line that is no event."""
    raw = line.encode("utf-8", "replace") if isinstance(line, str) else line
    if raw.startswith(_PREFIX):
        end = raw.find(b'"', len(_PREFIX))
        name = raw[len(_PREFIX) : end]
        if end > 0 and b"\\" not in name:
            return name.decode("utf-8", "replace")
    ev = parse(line)
    return ev.e if ev else None


def parse(line: bytes | str) -> Event | None:
    """The event on one line; None for a line that holds none (see the module's docstring)."""
    try:
        d = json.loads(line)
        return _event(d) if d.__class__ is dict else None
    except (ValueError, RecursionError):  # JSONDecodeError and UnicodeDecodeError are ValueErrors
        return None


def parse_lines(
    lines: Iterable[bytes | str], only: Collection[str] | None = None
) -> Iterator[Event]:
    """The events of `lines`, in order; with `only`, just the events named there (the other
    lines are not parsed)."""
    for line in lines:
        if only is not None and event_name(line) not in only:
            continue
        ev = parse(line)
        if ev is not None:
            yield ev


def read(path: str | os.PathLike[str], only: Collection[str] | None = None) -> list[Event]:
    """The events of the log at `path` ([] when there is none); with `only`, just those
    events. boundedfile.Refused when it is not a regular file of at most MAX_LOG_BYTES."""
    try:
        f = boundedfile.open_text(path)
    except boundedfile.Refused as r:
        if r.kind == "missing":
            return []
        raise
    size = os.fstat(f.fileno()).st_size
    if size > MAX_LOG_BYTES:
        f.close()
        raise boundedfile.Refused("too_big", size)
    # the bounded file's bytes again as text, a byte that is not UTF-8 read as U+FFFD
    raw = cast(io.TextIOWrapper, f).detach()
    text = io.TextIOWrapper(raw, encoding="utf-8", errors="replace", newline="")
    with text:
        if only is not None:
            return list(parse_lines((ln for ln in text if len(ln) <= MAX_LINE), only))
        out = []
        for line in text:
            ev = parse(line) if len(line) <= MAX_LINE else None
            if ev is not None:
                out.append(ev)
        return out
