"""JSON files that other processes may read at any time: written whole or not at all.

The one atomic write and the one tolerant read of the project (run results, sweep state,
testbed state, the AODV daemons' statistics, the routing-metrics cache).
"""

from __future__ import annotations

import json
import os
from typing import Any


def write_json_atomic(
    path: str | os.PathLike[str], obj: Any, *, sort_keys: bool = False, mode: int | None = None
) -> None:
    """`path` holds `obj` (indent 1, newline-terminated) or what it held before, never a part:
    the text goes to a temporary file of this process first and is renamed over `path`.
    `mode`: the file's permissions, whatever the umask (else the umask decides)."""
    tmp = f"{path}.{os.getpid()}.tmp"
    try:
        if mode is None:
            f = open(tmp, "w")
        else:
            flags = os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW
            fd = os.open(tmp, flags, mode)
            os.fchmod(fd, mode)
            f = os.fdopen(fd, "w")
        with f:
            f.write(json.dumps(obj, indent=1, sort_keys=sort_keys) + "\n")
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def read_json(path: str | os.PathLike[str]) -> Any:
    """The JSON in `path`, or None when it is missing, unreadable or not valid JSON (nested
    deeper than the parser's recursion allows included)."""
    try:
        with open(path) as f:
            return json.load(f)
    except (OSError, ValueError, RecursionError):
        return None
