"""Reading a file that someone else wrote, without trusting it: a regular file of bounded
size, opened without blocking, so that a FIFO, a device or /dev/zero is refused at once
rather than waited on or read without end. Used for movement traces, sweep files and map
pictures; each caller words the refusal for its own kind of file."""

from __future__ import annotations

import os
import stat
from collections.abc import Callable


class Refused(Exception):
    """Why a file was not read: `kind` is "unreadable" (with the OS's reason in `detail`),
    "missing", "directory", "special" (not a regular file) or "too_big" (`detail`: bytes)."""

    def __init__(self, kind: str, detail: str | int = ""):
        super().__init__(kind)
        self.kind = kind
        self.detail = detail


def read(path, limit: int, check: Callable[[int, os.stat_result], None] | None = None) -> bytes:
    """The whole content of `path`, a regular file of at most `limit` bytes; Refused if not.
    `check(fd, stat)` may look at the file before it is read (and raise its own error)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    except FileNotFoundError:
        raise Refused("missing") from None
    except OSError as exc:
        raise Refused("unreadable", exc.strerror or str(exc)) from None
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
