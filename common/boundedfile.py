"""Reading a file that someone else wrote, without trusting it: a regular file of bounded
size, opened without blocking, so that a FIFO, a device or /dev/zero is refused at once
rather than waited on or read without end. The one reader of every file the testbed takes
from a results directory (result.json, medium.json, sweep.json, the daemons' statistics,
network.json, captures' logs, relay-lag files), of movement traces, sweep files and map
pictures; each caller words the refusal for its own kind of file (`describe` gives the
reason as words).

`load_json` is the strict JSON of such a file: no NaN or Infinity, no number that is not
finite as a float (1e400) or longer than MAX_DIGITS digits, nesting no deeper than
MAX_DEPTH; anything else is Refused("not_json", why)."""

from __future__ import annotations

import json
import os
import stat
from collections.abc import Callable
from typing import Any, TextIO

MAX_JSON_BYTES = 64 << 20  # a 1000-robot result.json is under 5 MB
MAX_DEPTH = 64  # the testbed's own files nest at most 5 deep
MAX_DIGITS = 30  # more than any count or nanosecond time needs


class Refused(Exception):
    """Why a file was not read: `kind` is "unreadable" (with the OS's reason in `detail`),
    "missing", "directory", "special" (not a regular file), "too_big" (`detail`: bytes) or
    "not_json" (`detail`: why)."""

    def __init__(self, kind: str, detail: str | int = ""):
        super().__init__(kind)
        self.kind = kind
        self.detail = detail


def describe(r: Refused) -> str:
    """The refusal as words for a one-line message: "not a regular file (a FIFO, ...)"."""
    return {
        "missing": "no such file",
        "directory": "a directory, not a file",
        "special": "not a regular file (a FIFO, device or socket): not read",
        "too_big": f"too large ({r.detail} bytes)",
        "unreadable": f"unreadable ({r.detail})",
        "not_json": f"unreadable: not valid JSON ({r.detail})",
    }.get(r.kind, r.kind)


def read(
    path: str | os.PathLike[str],
    limit: int,
    check: Callable[[int, os.stat_result], None] | None = None,
) -> bytes:
    """The whole content of `path`, a regular file of at most `limit` bytes; Refused if not.
    `check(fd, stat)` may look at the file before it is read (and raise its own error)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except FileNotFoundError:
        raise Refused("missing") from None
    except (OSError, ValueError) as exc:  # ValueError: a NUL in the name
        raise Refused("unreadable", getattr(exc, "strerror", None) or str(exc)) from None
    try:
        st = os.fstat(fd)
        if stat.S_ISDIR(st.st_mode):
            raise Refused("directory")
        if not stat.S_ISREG(st.st_mode):
            raise Refused("special")
        if st.st_size > limit:
            raise Refused("too_big", st.st_size)
        if check is not None:
            check(fd, st)
        with os.fdopen(fd, "rb", closefd=False) as f:
            data = f.read(limit + 1)
    except OSError as exc:
        raise Refused("unreadable", exc.strerror or str(exc)) from None
    finally:
        os.close(fd)
    if len(data) > limit:  # it grew while it was read
        raise Refused("too_big", len(data))
    return data


def open_text(path: str | os.PathLike[str]) -> TextIO:
    """`path` opened for reading as UTF-8 text (newline="" for csv), checked to be a regular
    file on the descriptor it was opened on (never waiting on a FIFO, and no window between a
    check and the open); Refused if not. For files read line by line, whose rows the caller
    checks, rather than whole."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except FileNotFoundError:
        raise Refused("missing") from None
    except (OSError, ValueError) as exc:
        raise Refused("unreadable", getattr(exc, "strerror", None) or str(exc)) from None
    try:
        mode = os.fstat(fd).st_mode
    except OSError as exc:
        os.close(fd)
        raise Refused("unreadable", exc.strerror or str(exc)) from None
    if not stat.S_ISREG(mode):
        os.close(fd)
        raise Refused("directory" if stat.S_ISDIR(mode) else "special")
    return os.fdopen(fd, "r", encoding="utf-8", newline="")


def regular(path: str | os.PathLike[str]) -> bool:
    """Whether `path` is a regular file (links followed), found without opening it."""
    try:
        return stat.S_ISREG(os.stat(path).st_mode)
    except (OSError, ValueError):
        return False


def _constant(name: str) -> Any:
    raise ValueError(f"{name} is not a number JSON allows")


def _float(text: str) -> float:
    value = float(text)
    if value in (float("inf"), float("-inf")):
        raise ValueError(f"{text[:40]} is not a finite number")
    return value


def _int(text: str) -> int:
    if len(text.lstrip("-")) > MAX_DIGITS:
        raise ValueError(f"a number of {len(text)} digits")
    return int(text)


def _depth(text: str) -> int:
    """How deep brackets nest in JSON text (strings skipped), without recursion."""
    depth = deepest = 0
    in_string = escaped = False
    for c in text:
        if in_string:
            if escaped:
                escaped = False
            elif c == "\\":
                escaped = True
            elif c == '"':
                in_string = False
        elif c == '"':
            in_string = True
        elif c in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif c in "]}":
            depth -= 1
    return deepest


def parse_json(data: bytes | str) -> Any:
    """Strict JSON (see the module's docstring); Refused("not_json", why) otherwise."""
    try:
        text = data.decode("utf-8") if isinstance(data, bytes) else data
        if _depth(text) > MAX_DEPTH:
            raise ValueError(f"nested deeper than {MAX_DEPTH}")
        return json.loads(text, parse_constant=_constant, parse_float=_float, parse_int=_int)
    except (ValueError, RecursionError) as e:  # UnicodeDecodeError is a ValueError
        why = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise Refused("not_json", why[:200]) from None


def load_json(path: str | os.PathLike[str], limit: int = MAX_JSON_BYTES) -> Any:
    """The strict JSON in `path` (read), Refused if it is not a regular file of at most
    `limit` bytes holding such JSON."""
    return parse_json(read(path, limit))
