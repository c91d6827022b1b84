"""The analysis's runs: each finished run of a sweep as a `FinishedRun`, its result.json
(testbed.files.resultfile's `RunResult`) with where it lies and its channel's counters.

Theory of operation. Every module of testbed.analysis that needs what a run did (figures,
verdicts, the ablation, the protocols comparison, the causality check, the routing metrics)
takes a `FinishedRun`, made here once per run by `load_run`, instead of reading result.json
itself. A `FinishedRun` is a `RunResult` (so `run.status`, `run.config.robots`,
`run.exploration_steps` are the file's, read and checked by testbed.files.resultfile, with the
defaults of older files applied there) plus its run id and directory:

- A result.json the analysis cannot read (testbed.files.resultfile's `ResultError`: one line
  naming the file and the key) makes `load_run` raise; `load_runs` (a sweep directory) logs
  that line and leaves the run out, as a sweep's report counts what it could read.
- A run on the ns3-wifi medium also left `medium.json`, the 802.11 channel's counters
  (docs/ns3-medium.md, "Counters"): read into `FinishedRun.channel` (a `ChannelRecord`,
  testbed.files.mediumfile), None for a veth run or a run made before the file existed. A
  medium.json that is there but not what the channel writes makes the run malformed, as a
  bad result.json does; so does a relay-lag file (the channel's per-frame lag,
  testbed.analysis.relaylag) without its header.

Which runs count (`FinishedRun.usable`): status `complete` or `step_cap`, and faithful to
its time scale (result.json's `fidelity`, testbed.run.fidelity; a run written before verdicts
counts) unless `load_runs(..., unfaithful=True)` keeps those too; a run that hit the step
cap counts its unfinished robots at the final step (`exploration_steps`), and a robot
stopped on purpose (`--kill`) is not counted at all.

Whether a run's TCP kept emulated time (`tcp_in_emulated_time`: at time scale 1, or with
its network verdict `fidelity.network` ok) decides whether its PDF and delay may be set
beside another time scale's; a dilated run written before the network's timers were
dilated did not keep it.
"""

from __future__ import annotations

import dataclasses
import logging
import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

from common import boundedfile
from testbed.files import mediumfile
from testbed.files.mediumfile import ChannelRecord
from testbed.files.resultconfig import DEFAULT_VARIANT
from testbed.files.resultfile import RESULT_NAME, ResultError, RunResult
from testbed.files.resultvalues import one_line

if TYPE_CHECKING:  # only named: reading a result loads no routing.json type
    from testbed.files.routingfile import RoutingMetrics

log = logging.getLogger(__name__)

__all__ = ["DEFAULT_VARIANT", "FinishedRun", "ResultError", "load_run", "load_runs"]

USABLE = ("complete", "step_cap")
_NUM = (int, float)


@dataclass(frozen=True, kw_only=True)
class FinishedRun(RunResult):
    """A finished run of a sweep: its result.json, its directory and its channel's counters."""

    run_id: str
    path: Path
    channel: ChannelRecord | None = None  # medium.json: the ns3-wifi channel's counters
    count_unfaithful: bool = False  # usable even if not faithful (load_runs(unfaithful=True))

    @property
    def usable(self) -> bool:
        return self.status in USABLE and (self.faithful is not False or self.count_unfaithful)

    def captured_per_robot_s(self, metrics: RoutingMetrics, key: str) -> float | None:
        """A count of the run's capture metrics (routing.json's `key`) per transmitting robot
        (the display robot transmits too) per second of robot time; None when missing."""
        total, wall = metrics.count(key), metrics.duration_s
        return self.per_robot_second(total, wall, self.config.robots + 1)

    @classmethod
    def of(cls, result: RunResult, run_dir: Path, channel: ChannelRecord | None = None):
        fields = {f.name: getattr(result, f.name) for f in dataclasses.fields(RunResult)}
        return cls(**fields, run_id=one_line(run_dir.name), path=run_dir, channel=channel)


def _check_lag_file(run_dir: Path) -> None:
    """ResultError when the run's relay-lag file is there but not one (its header)."""
    from testbed.analysis import relaylag
    from topology.names import LAG_FILE

    path = run_dir / LAG_FILE
    if not os.path.lexists(path):
        return
    try:
        head = boundedfile.read(path, relaylag.MAX_LAG_BYTES)[: len(relaylag.MAGIC)]
    except boundedfile.Refused as r:
        raise ResultError(f"{path}: {boundedfile.describe(r)}") from None
    if head != relaylag.MAGIC:
        raise ResultError(f"{path}: not a relay-lag file (no {relaylag.MAGIC.decode()} header)")


def load_run(run_dir: str | Path) -> FinishedRun:
    """The finished run in `run_dir`; ResultError (one line, naming the file) when its
    result.json is missing, not JSON or lacks what the analysis needs, or its medium.json
    or relay-lag file is there but unreadable."""
    run_dir = Path(run_dir)
    channel = mediumfile.read(run_dir)
    _check_lag_file(run_dir)
    return FinishedRun.of(RunResult.from_json(run_dir), run_dir, channel)


def load_runs(
    sweep_dir: str | Path, unfaithful: bool = False, left_out: list[str] | None = None
) -> list[FinishedRun]:
    """Every run of a sweep directory with a readable result.json, sorted by run id; the
    others are logged and left out (and why appended to `left_out`, one line each).
    `unfaithful`: runs not faithful to their time scale count as usable too."""
    runs = []
    why = [] if left_out is None else left_out
    for run_dir in sorted(p.parent for p in Path(sweep_dir).glob(f"runs/*/{RESULT_NAME}")):
        if run_dir.is_symlink():  # its files (routing.json) would be written elsewhere
            why.append(f"{one_line(str(run_dir))}: a symbolic link, not a run directory")
            log.warning("skipping %s", why[-1])
            continue
        try:
            runs.append(replace(load_run(run_dir), count_unfaithful=unfaithful))
        except ResultError as e:
            why.append(one_line(str(e)))
            log.warning("skipping %s", why[-1])
    return runs
