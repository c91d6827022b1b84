"""A robot's event log: one JSON object per line, for the run to summarise and check.

Every record has "e" (the event) and "step" (the robot's step when it happened). The file is
line-buffered so a robot killed mid-run leaves every complete line behind.
"""

from __future__ import annotations

import json
import threading


class EventLog:
    def __init__(self, path: str | None):
        self.f = open(path, "a", buffering=1) if path else None  # noqa: SIM115
        self.lock = threading.Lock()

    def write(self, event: str, step: int, **fields) -> None:
        if self.f is None:
            return
        rec = {"e": event, "step": step, **fields}
        line = json.dumps(rec, separators=(",", ":"))
        with self.lock:
            self.f.write(line + "\n")

    def close(self) -> None:
        if self.f is not None:
            with self.lock:
                self.f.close()
                self.f = None
