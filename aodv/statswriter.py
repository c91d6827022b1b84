"""The daemon's statistics file, rewritten off the loop that serves its timers.

Theory of operation
-------------------
The loop (aodv.daemon) turns its statistics into text every STATS_PERIOD and hands the text
to `StatsWriter.submit`, which only stores it and wakes a writer thread; the thread writes the
newest text it was handed (common.jsonfile.write_atomic: a temporary file renamed over the
old one). A text handed in while a write is under way replaces any older one still waiting,
so a slow disk costs rewrites, never the loop's time.

Why a thread: the atomic rewrite creates a file in the run directory (the directory's lock,
shared with every other daemon writing there) and its rename frees the old file's blocks
(on a file system mounted with `discard`, a discard request waits in the disk's queue behind
whatever else is written). Traced beside a disk writer, those calls held a daemon's loop
in uninterruptible sleep for 20-50 ms each time, up to seconds, and both daemons of a run
at once: their HELLO timers fired late while every world step and robot plan was on time
(docs/measurements.md, "The AODV daemons' stalls"). The thread blocks in those system calls
without the interpreter's lock, so the loop goes on.

`close()` writes what is still waiting and joins the thread; the daemon then writes its
last, indented statistics itself (no deadline is due after the loop).
"""

from __future__ import annotations

import logging
import threading

from common.jsonfile import write_atomic

log = logging.getLogger(__name__)


class StatsWriter:
    """Writes the newest submitted text to `path` on a thread of its own."""

    def __init__(self, path: str) -> None:
        self.path = path
        self.writes = 0  # rewrites done
        self.skipped = 0  # texts replaced by a newer one before they were written
        self.failures = 0  # rewrites the file system refused
        self._pending: str | None = None
        self._closing = False
        self._cond = threading.Condition()
        self._thread = threading.Thread(target=self._run, name="aodv-stats", daemon=True)
        self._thread.start()

    def submit(self, text: str) -> None:
        """Hand over the file's next contents; returns at once."""
        with self._cond:
            if self._pending is not None:
                self.skipped += 1
            self._pending = text
            self._cond.notify()

    def close(self) -> None:
        """Write what is waiting, then stop the thread (idempotent)."""
        with self._cond:
            self._closing = True
            self._cond.notify()
        self._thread.join()

    def _run(self) -> None:
        while True:
            with self._cond:
                while self._pending is None and not self._closing:
                    self._cond.wait()
                text, self._pending = self._pending, None
                closing = self._closing
            if text is not None:
                try:
                    write_atomic(self.path, text)
                    self.writes += 1
                except OSError as e:  # a full disk must not end the daemon; said once a while
                    self.failures += 1
                    if self.failures % 100 == 1:
                        log.warning(
                            "statistics file %s not written (%d times): %s",
                            self.path,
                            self.failures,
                            e,
                        )
            if closing:
                return
