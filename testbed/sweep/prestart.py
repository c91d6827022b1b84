"""Pre-started runs of a sweep (testbed.sweep.runner): their start gates, when the gates
open, and what becomes of a pre-started run that never stepped.

Theory of operation. While exactly one run steps, the next run that would fit once that one
is in its tail starts beside it already (Schedule.prestart_next) with `--start-when
DIR/logs/R.gate`: it prepares, brings its network up, starts and connects its processes and
then waits, its step clock not started, until the sweep creates that file, which it does
when the stepping run's steps are over (its steps-over file) or it exited. Its set-up (about
1.2 s a run in the paper sweep: the child's start, prepare(), network up, processes ready)
is then off the critical path, and its lateness and fidelity mean what they always did: its
clock starts at the gate (result.json's wall_parts_s.gate_wait says how long it waited). A
run that stepped while the next one pre-started beside it and was late turns pre-start off
beside its team size until enough of its runs came out clean (testbed.sweep.policy, rules 3a
and 9a); with --view or --no-prestart there is none. A gate that stays shut for
--start-timeout (set from the stepping run's own step budget: it hangs) ends the waiting run
with status `gate_timeout`; the sweep redoes it, not counted as an attempt, and pre-starts
no other run beside the hung one. On SIGINT a waiting run tears its testbed down as any run
does. A run pre-started at a time scale that the outcome of the run before it changed (that
run exited before its steps-over file, so the gate was still shut) is stopped at its gate
and started again at the new scale, not counted as an attempt; once its gate is open it
keeps its scale, as a run started during a tail does.
"""

from __future__ import annotations

import contextlib
import logging
import signal
import time
from collections import deque
from pathlib import Path
from typing import Any

from testbed.files.runconfig import RunConfig
from testbed.sweep.schedule import Schedule, note_sharing

log = logging.getLogger(__name__)

# Seconds a pre-started run waits at its start gate beyond the step budget of the run before
# it (its steps at its time scale, GATE_SLACK times over): then that run hangs.
GATE_MARGIN_S = 120.0
GATE_SLACK = 3.0
GATE_TIMEOUT_STATUS = "gate_timeout"  # result.json's status of a run whose gate timed out


def gate_file(out: Path, run_id: str) -> Path:
    """The file that opens pre-started run `run_id`'s steps (`testbed run --start-when`)."""
    return out / "logs" / f"{run_id}.gate"


def gate_timeout(before: RunConfig) -> float:
    """How long a run pre-started beside a run of config `before` (at the time scale it got)
    waits at its gate: that run's step budget GATE_SLACK times over, plus GATE_MARGIN_S."""
    steps_s = before.max_steps * 0.1 / max(before.time_scale, 1e-3)
    return GATE_SLACK * steps_s + GATE_MARGIN_S


def open_gates(children: dict[str, Any], schedule: Schedule, out: Path) -> bool:
    """Create the gate of each pre-started run (testbed.sweep.runner._Child) whose awaited
    run's steps are over (or it exited): its steps start now, beside the runs in flight then,
    as a run started now would (`shared`, the loads seen; `overlapped` by the tail that
    opened it). One whose time scale the awaited run's outcome changed is stopped instead
    (SIGINT: its testbed torn down; `redo_cancelled`). Returns whether any gate opened."""
    opened = False
    for child in children.values():
        ahead = children.get(child.awaits)
        if not child.gated or (ahead is not None and not ahead.tail):
            continue
        if ahead is None and child.config != schedule.scaled(child.run):
            if not child.cancelled:
                child.cancelled = True
                with contextlib.suppress(ProcessLookupError):
                    child.proc.send_signal(signal.SIGINT)
            continue
        try:
            gate_file(out, child.run.run_id).touch()
        except OSError as e:
            log.warning("cannot open the start gate of %s: %s", child.run.run_id, e)
            continue
        child.gated, opened = False, True
        child.gate_wait = time.monotonic() - child.started
        note_sharing([c for c in schedule.beside(child.run, children) if not c.gated])
    return opened


def redo_cancelled(child: Any, st: dict, queue: deque) -> str:
    """A run stopped at its gate (`open_gates`) goes next, after the run it waited for if
    that one is redone, not counted as an attempt; returns the progress line's event."""
    st.pop("prestarted", None)
    st["status"], st["attempts"] = "pending", st["attempts"] - 1
    first = queue and queue[0].run_id == child.awaits
    queue.insert(1 if first else 0, child.run)
    return f"{child.run.run_id}: pre-started at a time scale changed since, starting it again"


def redo_shut(child: Any, detail: str, st: dict, queue: deque, children: dict) -> str:
    """A run whose gate stayed shut (status gate_timeout: the run before it hangs) is redone
    first, not counted as an attempt, and no run is pre-started beside the hung one again;
    returns the progress line's event."""
    ahead = children.get(child.awaits)
    if ahead is not None:
        ahead.no_prestart_beside = True
    st["status"], st["attempts"] = "pending", st["attempts"] - 1
    queue.appendleft(child.run)
    return f"{child.run.run_id}: its start gate stayed shut ({detail}), redoing it"
