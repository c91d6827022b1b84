"""JSON files that readers may look at any time: written whole or not at all."""

from __future__ import annotations

import json
import os


def write_json_atomic(path, obj) -> None:
    """`path` holds `obj` (indent 1, newline-terminated) or what it held before: the text goes
    to `path.tmp` first and is renamed over `path`."""
    tmp = f"{path}.tmp"
    with open(tmp, "w") as f:
        f.write(json.dumps(obj, indent=1) + "\n")
    os.replace(tmp, path)


def read_json(path):
    """The JSON in `path`, or None when it is missing or not valid JSON."""
    try:
        with open(path) as f:
            return json.load(f)
    except (OSError, ValueError):
        return None
