"""The fidelity verdict of a run: did time dilation leave the robots' behaviour as it was?

Theory of operation. `--time-scale K` runs emulated time K times faster than the wall clock.
That is harmless while every piece of work that belongs to a step is done within the step,
as it would be on the robots' own processors at K = 1; it changes the answer when the work
completes late *in emulated time*, because the robots act on the step at which it arrives.

The mechanism, measured (a lone robot, empty terrain, laser 2 m, range 20 m, AODV; the
machine loaded by other work, load average 2-5, 2 cores). A robot's plan is asked for at
step s (by its timer, every 20 steps, or at the start) and computed from the map and the
pose of that step; it is applied at the first frame the motion thread answers after the
planner installed it. On time, that is step s + 1. Planning costs 1-2 ms of wall time
(median 1.2 ms, up to ~10 ms), i.e. 6-20% of a step at K = 5 but 70-100% of a step at
K = 60 (1.67 ms): there, most plans are applied one to six steps late (seed 2: 96 of 130
plans late, against 1 of 99 at K = 5). The plan's path starts at the cell where the robot
was when it asked, so a late plan first drives the robot back to where it was, then on
(seed 2: 200 reversals of direction at K = 60 against 52 at K = 5; path 248 m against
188 m), and every later plan is computed from a different pose and map: 2602 steps
instead of 1989 (+31%). The timer's own lateness (it fires a step after it is due) shifts
every later plan by as much. The lone robot took exactly the same steps only where no plan
and no timer was late (seed 1 at K = 5: 0 of 95 plans late, 1901 steps, as at K = 15 on a
quiet machine); one late plan already moves it (seed 2: 1 of 99 late and 2 timers, 1991
steps for 1989), because exploration is chaotic: a path that differs once differs after.
All the numbers are in docs/architecture.md ("Time dilation and fidelity").

Since then the robot keeps that order itself (node.motion `_keep_step_order`): motion control
holds a frame until the previous step's plan and timer are done, for at most three quarters
of a step, so a plan comes late only when the host cannot compute it within that: a lone
robot now takes exactly the same steps at K = 5 and K = 30 (seeds 1-3), and at K = 60 one
plan in ten is still late, which this verdict reports.

The verdict: a run is faithful when, over all its robots and daemons,

- the step deadlines missed outside host stalls are at most DEADLINE_MISS_LIMIT (the
  sweep's limit: a missed deadline is a frame answered after the world moved on);
- the plans applied late (age >= 1 step) are at most LATE_PLAN_LIMIT (1%) of the plans
  applied, and so are the plan timers that fired late. Exactness needs none; the verdict
  tolerates one plan in a hundred (one of a lone robot's run, ten of a ten-robot team's),
  which a team's run-to-run noise covers if anything does (docs/architecture.md, "Invariance
  for teams", measures it).
  A calibration trial (300 steps, ~15 plans a robot) must have none.
  Decided (2026-11-27): a late plan counts against a run through this share only, whether or
  not it changed what the robot did. Whether it did cannot be told from the run (a late plan
  to the goal the robot was already driving to changes nothing); a lone robot's run is
  deterministic, so there one late plan may change its steps (seed 3 at K = 5 took 2084
  steps for 1964 under a load of 4 with one late plan, judged faithful), while a team's
  runs differ by tens of percent between seeds and one plan in a hundred is within that. So
  `late_plans` is recorded in every verdict, and a check that needs a lone run exactly (the
  exactness test) reads only runs with none;
- no AODV HELLO timer fired more than HELLO_LATE_LIMIT_MS emulated ms late, and no expiry
  timer more than EXPIRY_LATE_LIMIT_MS, while the robots stepped (a timer late before step 0
  or after the last step, while the processes start or write their results, changes no
  robot's run; each daemon keeps its most late firings with their times: `_late_within`). A
  neighbour drops a link after ALLOWED_HELLO_LOSS x HELLO_INTERVAL (2 s) of silence, so a
  HELLO breaks a link that exists only when it comes one HELLO_INTERVAL (1 s) late; the
  limit is half that. An expiry timer that fires late detects a true break, or drops a dead
  route, that much later (against 2-3 s): its limit is a quarter of HELLO_INTERVAL;
- the display handled at most DISPLAY_LATE_LIMIT of its frames more than two steps late
  (its beacons, which tell robots it is back in reach, follow its frames);
- on ns3-wifi, the channel relayed frames at most CHANNEL_LAG_LIMIT_MS late on average
  (emulated ms, medium.json's `relay_lag`). A frame relayed d ms late reaches its robot in a
  later step than on time with probability d / 100 ms, so a mean lag of 1 ms puts about 1%
  of the messages into a later step: the limit plans have. (Delay measured on the channel
  takes the lag in whole; the report's channel table shows it per point.)

A robot's "done" that reached the world after the deadline of the step it was decided at is
counted (`late_dones`, `done_late_max_steps`) but is no reason: the robot's finish is the step
its message says (testbed.run.record), so exploration times are as the robot decided them;
the world only ran that much longer (`steps`, and positions.csv's rows after the robot
stopped). The robots send it before answering any later frame, so it comes late only when
the planner itself decided after that deadline. The exactness test reads only runs without.

Where the path can be known it is checked, not estimated: a lone robot's run is held against
its in-process twin (testbed.run.twin: the same world, robot code, seed and phase stepped in
one thread as a run where nothing is late steps them, exact to the K = 5 runs of seeds 1-3),
and a run whose positions differ from the twin's is not faithful, whatever its share of late
work, with the step it left the twin at ("the path differs from its in-process twin from
step N"). This supersedes the 1% tolerance above for lone robots: whether a late plan (or
a late answer to a frame, which no measure above counts as late work) changed the path is
no longer a guess. `with_twin` adds the check to a verdict; result.json's `fidelity.twin`
records it, or why the twin does not apply (a team, --kill, --isolate, a run that did not
end by itself). Measured (2026-11-29, 2 cores, load 2-3.5): at K = 100, seeds 2, 3 and 4
each stood still at step 2 (seed 2 answered frames 0 and 1 after their deadlines: 2 of
1989, no plan late), ran a step behind their twins for 20 steps, then in step again, with
the K = 5 step counts, and seeds 2 and 4 were judged faithful without the twin; at K = 5,
seed 1 beside host stalls missed 9 deadlines (4 outside the stalls, 0.1%; no plan late)
and left its twin at step 1523 for the rest of its run (the same 1901 steps), judged
faithful without the twin.

A run during whose steps the host's ARP table was full (topology.kernel.neightable) is not
faithful either (`with_neighbour_table`): the kernel dropped sends that needed an entry,
silently for UDP, so AODV's messages and the map floods were lost at the sender, which no
lateness measure sees.

`measures(...)` folds the per-process records (node.lateness dicts, the AODV daemons'
`timer_lateness_ms`) into one `Measures`; `verdict(...)` judges them; both are pure.

The network has its own verdict (`network_verdict`, result.json's `fidelity.network`): the
kernel's TCP timers are divided by the time scale where the kernel lets them be
(topology.kernel.nettimers), and a dilated run whose kernel could not dilate TCP's retransmission
timeout (no `tcp_rto_min_us` before Linux 6.11, or a time scale past its jiffy) says so. Its
PDF and delay then mean something else than at another time scale, and the report does not
set them beside another scale's; its exploration does not depend on it (steps, plans and
control overhead agreed within the noise with TCP undilated: docs/architecture.md), so it
leaves `ok` alone.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass
from typing import Any

from aodv.params import Params as AodvParams
from node.timing import STEP_S
from testbed.files.mediumfile import RelayLag
from topology.kernel.nettimers import NetworkTimers

DEADLINE_MISS_LIMIT = 0.01
LATE_PLAN_LIMIT = 0.01
_RFC = AodvParams()  # both AODV profiles send a HELLO every 1 s and allow 2 to be lost
# Half of how late a HELLO must come to break a link: (ALLOWED_HELLO_LOSS - 1) x HELLO_INTERVAL.
HELLO_LATE_LIMIT_MS = 0.5 * (_RFC.allowed_hello_loss - 1) * _RFC.hello_interval_ms
EXPIRY_LATE_LIMIT_MS = 250.0
DISPLAY_LATE_LIMIT = 0.05
STEP_MS = STEP_S * 1000
CHANNEL_LAG_LIMIT_MS = LATE_PLAN_LIMIT * STEP_MS  # mean relay lag: 1% of messages a step late
DISPLAY_LATE_MS = 200  # "more than two steps late": a bound of node.lateness.MS_BOUNDS


@dataclass(frozen=True)
class Thresholds:
    deadline_miss_fraction: float = DEADLINE_MISS_LIMIT
    late_plan_fraction: float = LATE_PLAN_LIMIT
    late_timer_fraction: float = LATE_PLAN_LIMIT
    hello_late_max_ms: float = HELLO_LATE_LIMIT_MS
    expiry_late_max_ms: float = EXPIRY_LATE_LIMIT_MS
    display_late_fraction: float = DISPLAY_LATE_LIMIT
    channel_lag_mean_ms: float = CHANNEL_LAG_LIMIT_MS


@dataclass(frozen=True)
class Measures:
    """A run's lateness, over all its robots (and daemons); None: not measured (an older
    run, a run without that process)."""

    deadline_miss_fraction: float | None = None  # outside host stalls
    plans: int = 0  # plans applied
    late_plans: int = 0  # applied one step or more late
    plan_age_max_steps: float = 0
    timers: int = 0  # plan timer firings
    late_timers: int = 0
    timer_late_max_steps: float = 0
    late_dones: int = 0  # robots whose "done" reached the world late: counted, not judged
    done_late_max_steps: int = 0
    hello_late_max_ms: float | None = None
    expiry_late_max_ms: float | None = None
    display_frames: int = 0
    display_late_frames: int = 0  # handled more than DISPLAY_LATE_MS after the world sent them
    channel_frames: int = 0  # frames the ns3-wifi channel relayed
    channel_lag_mean_ms: float | None = None  # how late, on average (None: no such channel)

    @property
    def late_plan_fraction(self) -> float:
        return round(self.late_plans / self.plans, 4) if self.plans else 0.0

    @property
    def late_timer_fraction(self) -> float:
        return round(self.late_timers / self.timers, 4) if self.timers else 0.0

    @property
    def display_late_fraction(self) -> float:
        if not self.display_frames:
            return 0.0
        return round(self.display_late_frames / self.display_frames, 4)


def _late_over(hist: dict, bound: float) -> int:
    """Events of a node.lateness histogram above `bound` (one of its bounds)."""
    total = 0
    for label, n in hist.items():
        b = float(label.lstrip("<=>"))
        if label.startswith(">") or b > bound:
            total += n
    return total


def _late_within(timer: dict, stepping: tuple[float, float] | None) -> float:
    """The most a daemon's timer of one kind (its `timer_lateness_ms` entry) was late while
    the robots stepped (`stepping`: CLOCK_MONOTONIC seconds of the first and last step): the
    most late of its kept firings whose lateness overlapped the steps. When the daemon fired
    more than it kept, one it did not keep was at most as late as its least late kept one,
    which bounds the answer from above. Without times (an older daemon) or steps, its
    maximum over its whole life."""
    worst = timer.get("worst")
    if stepping is None or not isinstance(worst, list):
        return float(timer.get("max", 0.0))
    t0, t1 = stepping
    inside = [ms for due, fired, ms in worst if fired >= t0 and due <= t1]
    if worst and timer.get("n", 0) > len(worst):
        inside.append(min(ms for _, _, ms in worst))
    return float(max(inside, default=0.0))


def measures(
    miss_fraction: float | None,
    robots: Iterable[dict | None],
    display: dict | None = None,
    daemons: Iterable[Mapping[str, Any] | None] = (),
    channel: RelayLag | None = None,
    stepping: tuple[float, float] | None = None,
    done_late: Iterable[int] = (),
) -> Measures:
    """Fold the records into Measures: `robots` are the robots' `lateness` dicts (None: the
    robot left none), `display` the display's, `daemons` the AODV daemons'
    `timer_lateness_ms` dicts (judged within `stepping`, `_late_within`), `channel` the
    ns3-wifi channel's `relay_lag` (medium.json, read by testbed.files.mediumfile),
    `done_late` each robot's steps between deciding it was done and the world having it
    (testbed.run.record)."""
    dones = [d for d in done_late if d > 0]
    plans = late_plans = timers = late_timers = 0
    age_max = timer_max = 0.0
    for r in robots:
        if not isinstance(r, dict):
            continue
        p, t = r.get("plan_age_steps") or {}, r.get("plan_timer_steps") or {}
        plans += p.get("n", 0)
        late_plans += p.get("late", 0)
        age_max = max(age_max, p.get("max", 0))
        timers += t.get("n", 0)
        late_timers += t.get("late", 0)
        timer_max = max(timer_max, t.get("max", 0))
    hello = expiry = None
    for d in daemons:
        if not isinstance(d, Mapping):
            continue
        h, e = d.get("hello") or {}, d.get("expiry") or {}
        hello = max(hello or 0.0, _late_within(h, stepping))
        expiry = max(expiry or 0.0, _late_within(e, stepping))
    frames = late_frames = 0
    f = (display or {}).get("frame_done_ms")
    if f:
        frames, late_frames = f.get("n", 0), _late_over(f.get("hist", {}), DISPLAY_LATE_MS)
    relayed, lag = 0, None
    if channel is not None and channel.mean_ms is not None:
        relayed, lag = channel.frames, round(float(channel.mean_ms), 3)
    return Measures(
        deadline_miss_fraction=miss_fraction, plans=plans, late_plans=late_plans,
        plan_age_max_steps=age_max, timers=timers, late_timers=late_timers,
        timer_late_max_steps=timer_max, late_dones=len(dones),
        done_late_max_steps=max(dones, default=0), hello_late_max_ms=hello,
        expiry_late_max_ms=expiry,
        display_frames=frames, display_late_frames=late_frames,
        channel_frames=relayed, channel_lag_mean_ms=lag,
    )  # fmt: skip


def verdict(m: Measures, th: Thresholds = Thresholds()) -> dict:
    """result.json's `fidelity`: {ok, reason (when not ok), measures, thresholds}."""
    checks = (
        ("deadline_miss_fraction", m.deadline_miss_fraction, "of step deadlines missed", None),
        ("late_plan_fraction", m.late_plan_fraction, "plans applied a step or more late",
         (m.late_plans, m.plans)),
        ("late_timer_fraction", m.late_timer_fraction, "plan timers fired late",
         (m.late_timers, m.timers)),
        ("hello_late_max_ms", m.hello_late_max_ms, "ms: an AODV HELLO timer fired that late",
         None),
        ("expiry_late_max_ms", m.expiry_late_max_ms, "ms: an AODV expiry timer fired that late",
         None),
        ("display_late_fraction", m.display_late_fraction,
         "display frames handled over two steps late", (m.display_late_frames, m.display_frames)),
        ("channel_lag_mean_ms", m.channel_lag_mean_ms,
         "ms: the 802.11 channel relayed frames that late on average", None),
    )  # fmt: skip
    reasons = []
    for key, value, words, counts in checks:
        limit = getattr(th, key)
        if value is None or value <= limit:
            continue
        if counts:  # "3 of 99 plans applied ... (3.0%, limit 1.0%)"
            share = counts[0] / counts[1]
            reasons.append(f"{counts[0]} of {counts[1]} {words} ({share:.1%}, limit {limit:.1%})")
        elif key.endswith("fraction"):
            reasons.append(f"{value:.1%} {words} (limit {limit:.1%})")
        else:
            reasons.append(f"{value:g} {words} (limit {limit:g})")
    out: dict = {"ok": not reasons}
    if reasons:
        out["reason"] = "; ".join(reasons)
    values = asdict(m)
    values.update(
        late_plan_fraction=m.late_plan_fraction,
        late_timer_fraction=m.late_timer_fraction,
        display_late_fraction=m.display_late_fraction,
    )
    out["measures"] = values
    out["thresholds"] = asdict(th)
    return out


def with_twin(verdict: dict, twin: dict | str) -> dict:
    """`verdict` with its run's twin check (testbed.run.twin.check) under `twin`: a lone
    robot's path that differs from its in-process twin makes the run not faithful, whatever
    its share of late work, with the step it left the twin at in the reason; a path equal to
    it, or a run the twin does not cover ("not applicable: ..."), leaves `ok` as it was."""
    reasons = [verdict["reason"]] if verdict.get("reason") else []
    differs = isinstance(twin, dict) and twin.get("ok") is False
    if isinstance(twin, dict) and differs:
        step, n = twin.get("differs_from_step"), twin.get("steps_differing")
        why = f"the path differs from its in-process twin from step {step}"
        reasons.append(why + (f" ({n} steps differ)" if n else ""))
    out: dict = {"ok": bool(verdict.get("ok")) and not differs}
    if reasons:
        out["reason"] = "; ".join(reasons)
    out.update((k, v) for k, v in verdict.items() if k not in ("ok", "reason"))
    out["twin"] = twin
    return out


def with_neighbour_table(verdict: dict, fulls: int | None, limit: int | None) -> dict:
    """`verdict` with the host's ARP table over the steps under `neighbour_table` ({fulls,
    limit}; topology.kernel.neightable): a table that was full while the robots stepped made
    the kernel drop sends that needed a new entry, silently for UDP (AODV's messages, the
    map floods), so the run is not faithful, whatever else it measured. None: not read."""
    out = dict(verdict)
    out["neighbour_table"] = {"fulls": fulls, "limit": limit}
    if fulls:
        why = (
            f"the host's neighbour (ARP) table was full {fulls} times during the steps "
            f"(limit {limit}, net.ipv4.neigh.default.gc_thresh3): the kernel dropped sends"
        )
        out["ok"] = False
        out["reason"] = "; ".join(r for r in (verdict.get("reason"), why) if r)
    return out


def network_verdict(timers: dict | None, time_scale: float) -> dict:
    """result.json's `fidelity.network` from its `network_timers` (topology.kernel.nettimers'
    record): {ok, reason (when not ok)}. At time scale 1 the network is in emulated time by
    definition; dilated, when TCP's retransmission timeout was dilated."""
    if time_scale == 1:
        return {"ok": True}
    if not isinstance(timers, dict):
        return {"ok": False, "reason": "no record of the network's timers: TCP's ran on the "
                "wall clock"}  # fmt: skip
    try:
        record = NetworkTimers.from_dict(timers)
    except ValueError as e:
        return {"ok": False, "reason": f"the network timers' record is unreadable ({e})"}
    if record.tcp_dilated:
        return {"ok": True}
    return {"ok": False, "reason": record.tcp_reason}
