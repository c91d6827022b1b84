"""The sweep's progress line: a plain-text bar with the runs done, running and failed, the
elapsed time and an ETA from the mean run time per team size."""

from __future__ import annotations

import sys
import time

from testbed.sweep.file import PlannedRun


def _hms(seconds: float) -> str:
    seconds = int(max(0, seconds))
    h, rem = divmod(seconds, 3600)
    m, s = divmod(rem, 60)
    return f"{h}h{m:02d}m{s:02d}s" if h else f"{m}m{s:02d}s"


class Progress:
    """A plain-text progress bar with ETA on a stream: \\r-updated on a TTY, else one line per
    finished run."""

    WIDTH = 24

    def __init__(self, total: int, stream=None):
        self.total = total
        self.stream = stream if stream is not None else sys.stderr
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.start = time.monotonic()
        self.durations: dict[int, list[float]] = {}  # robots -> wall times this session
        self._last = ""

    def record(self, robots: int, seconds: float) -> None:
        self.durations.setdefault(robots, []).append(seconds)

    def parallelism(self) -> float:
        """Runs in flight on average so far: run wall time finished over sweep wall time."""
        busy = sum(d for ds in self.durations.values() for d in ds)
        return max(1.0, busy / max(1e-9, time.monotonic() - self.start))

    def eta(self, remaining: list[PlannedRun], running: int, jobs: float) -> float | None:
        """Seconds left: each remaining run costs the mean time of finished runs with the same
        team size (or the overall mean), shared over the concurrency."""
        all_d = [d for ds in self.durations.values() for d in ds]
        if not all_d:
            return None
        overall = sum(all_d) / len(all_d)
        total = 0.0
        for run in remaining:
            ds = self.durations.get(run.config.robots)
            total += sum(ds) / len(ds) if ds else overall
        total += running * overall / 2  # runs in flight are half done on average
        return total / max(1, jobs)

    def line(self, done: int, running: int, failed: int, eta: float | None) -> str:
        frac = done / self.total if self.total else 1.0
        filled = int(round(frac * self.WIDTH))
        bar = "#" * filled + "-" * (self.WIDTH - filled)
        eta_s = _hms(eta) if eta is not None else "?"
        elapsed = _hms(time.monotonic() - self.start)
        text = f"[{bar}] {done}/{self.total} done, {running} running"
        if failed:
            text += f", {failed} failed"
        return text + f", elapsed {elapsed}, ETA {eta_s}"

    def update(self, done, running, failed, eta, event: str | None = None) -> None:
        text = self.line(done, running, failed, eta)
        if self.tty:
            pad = max(0, len(self._last) - len(text))
            if event:
                self.stream.write("\r" + event + " " * max(0, len(self._last) - len(event)) + "\n")
                pad = 0
            self.stream.write("\r" + text + " " * pad)
            self._last = text
        elif event:
            self.stream.write(f"{event}  | {text}\n")
        self.stream.flush()

    def close(self) -> None:
        if self.tty and self._last:
            self.stream.write("\n")
            self.stream.flush()
