"""Which middleware a team can rely on: the paper's Section 3 measured.

Theory of operation
-------------------
The paper (Section 3) chose nanomsg over ZeroMQ because, "without a send timeout, in case of
a fall, the whole system of robots gradually stops because of waiting a response from each
other". A middleware sweep (testbed/experiments/middleware.toml) runs every point (team
size, range) once per middleware (`--middleware`, docs/middleware.md) and per battery
failure (`--battery-failure none|midrun`: robot rN killed at the team's mid-run step,
testbed.files.failures), on the same seeds. Per run (`run_row`):

- exploration steps: result.json's mean over the robots not stopped (the killed robot's
  exploration was cut short, not slow); a survivor that never finished counts the final
  step, so a team that stopped shows the step cap;
- whether the survivors finished (`survivors_finished`: every robot neither stopped nor
  crashed finished before the step cap);
- delivery, from the messengers' counters (result.json `messaging.team`): received / sent,
  sends that failed, duplicates and late arrivals. The killed robot leaves no counters, so
  what it received before it died is missing from `received`: with the failure, delivery
  reads low by about that much;
- blocked time: the team's wall seconds inside `send()` per robot-second of the step loop's
  wall time (blocked_s / (robots that left counters x step_loop_wall_s): the share of the
  robots' time spent waiting on a send), and the longest single send (`blocked_max_s`);
- the air cost, from the captures' `middleware` class (routing.json, testbed.analysis.
  pcapmetrics): the middleware's bytes on the wire per robot per second of robot (emulated)
  time, and the middleware's own share of them (`protocol_bytes / tx_bytes`: framing,
  greetings, commands, replies). A middleware the captures have no class for is "not
  measured".

`point_rows` gives each measure's mean with its 95% interval (Student t, stats.mean_ci) per
(team, range, failure, middleware), and the survivors' share with its Wilson interval.

The verdict (`VERDICT_RULE`, fixed before the sweep ran; `middleware_verdict`,
`paper_verdict`). Per middleware, over the points that ran it both without and with the
failure, pooled: N, the share of runs without the failure whose survivors finished, and F,
the same with one robot killed at mid-run, each with its 95% Wilson interval
(stats.share_ci). The claim *holds* for the middleware (the team stops) when N >= 90%,
F < 50% and the two intervals do not overlap; it *does not hold* (the team carries on) when
N >= 90% and F >= 90%; with fewer than MIN_RUNS runs in either mode it is *too few runs to
decide*; anything else is *undecided* (a team that does not finish even without the failure,
or a share in between). For the paper's reading: it holds when the claim holds for
zeromq-reqrep (ZeroMQ used naively, request and reply without a timeout) and does not hold
for every bounded-send middleware that ran (nanomsg, zeromq with SNDTIMEO, zenoh, dds); it
does not hold when it does not hold for zeromq-reqrep or holds for a bounded-send one; else
it is undecided, or too few runs when a middleware it needs had too few.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields

from node.messaging import DEFAULT as DEFAULT_MIDDLEWARE
from node.messaging import MIDDLEWARES
from testbed.analysis import stats
from testbed.analysis.rows import INLINE, MeanCI, Measures
from testbed.analysis.runs import FinishedRun
from testbed.analysis.verdictwords import FAILS, HOLDS, TOO_FEW
from testbed.files.failures import MIDRUN, NONE
from testbed.files.routingfile import MiddlewareTraffic, RoutingMetrics

UNDECIDED = "undecided"
NAIVE = "zeromq-reqrep"
BOUNDED = tuple(m for m in MIDDLEWARES if m != NAIVE)
FAILURE_ORDER = (NONE, MIDRUN)
FINISH_WITHOUT_MIN = 0.9  # Y: the survivors finish in at least this share without the failure
STOP_WITH_MAX = 0.5  # X: ... and in fewer than this share with it, for the team to "stop"
MIN_RUNS = 4  # runs a middleware needs in each mode, pooled over points, to be judged
PAPER_CLAIM = (
    "without a send timeout, in case of a fall, the whole system of robots gradually stops "
    "because of waiting a response from each other"
)
VERDICT_RULE = (
    "Per middleware, over the points that ran it without and with the failure, pooled: N is "
    "the share of runs without the failure whose survivors all finished, F the same with one "
    "robot killed at mid-run, each with its 95% Wilson interval. The claim holds for the "
    f"middleware (the team stops) when N >= {FINISH_WITHOUT_MIN:.0%}, F < "
    f"{STOP_WITH_MAX:.0%} and the two intervals do not overlap; it does not hold (the team "
    f"carries on) when N >= {FINISH_WITHOUT_MIN:.0%} and F >= {FINISH_WITHOUT_MIN:.0%}; "
    f"with fewer than {MIN_RUNS} runs in either mode there are too few runs to decide; "
    "anything else is undecided. The paper's reading (ZeroMQ stops the team, a send timeout "
    "saves it) holds when the claim holds for zeromq-reqrep and does not hold for every "
    "bounded-send middleware that ran (nanomsg, zeromq, zenoh, dds); it does not hold when "
    "it does not hold for zeromq-reqrep or holds for a bounded-send one; else it is "
    "undecided (or too few runs)."
)
# (key, name in the table, format); each a mean over the point's runs with its 95% interval
MEANS = (
    ("steps", "exploration steps", ".0f"),
    ("delivery", "delivery (received / sent)", ".3f"),
    ("failed", "failed sends", ".1f"),
    ("duplicates", "duplicates", ".1f"),
    ("late", "late arrivals", ".1f"),
    ("blocked_share", "blocked per robot-second", ".4f"),
    ("blocked_max_s", "longest send (s)", ".3f"),
    ("air_bytes_per_robot_s", "air bytes / robot / s", ".0f"),
    ("air_own_share", "middleware's own share", ".3f"),
)


@dataclass(frozen=True)
class MiddlewareRun:
    """One run's numbers for the middlewares' comparison."""

    run: str
    middleware: str
    battery_failure: str
    comm_range: float
    robots: int
    steps: float | None
    survivors_finished: int | None  # 1: every robot not stopped finished; None: unknown
    delivery: float | None
    failed: float | None
    duplicates: float | None
    late: float | None
    blocked_share: float | None
    blocked_max_s: float | None
    sending: float | None
    air_bytes_per_robot_s: float | None
    air_own_share: float | None


@dataclass(frozen=True)
class MiddlewareMeans(Measures):
    """The MEANS of a point: each one's mean over its runs with its 95% interval."""

    steps: MeanCI
    delivery: MeanCI
    failed: MeanCI
    duplicates: MeanCI
    late: MeanCI
    blocked_share: MeanCI
    blocked_max_s: MeanCI
    air_bytes_per_robot_s: MeanCI
    air_own_share: MeanCI


@dataclass(frozen=True)
class MiddlewarePoint:
    """Per (team, range, failure, middleware): the MEANS with their intervals, and the
    survivors' share of runs with its Wilson interval."""

    robots: int
    comm_range: float
    battery_failure: str
    middleware: str
    n: int
    left_out: int  # the point's runs the report did not count
    means: MiddlewareMeans = field(metadata=INLINE)
    survivors_runs: int
    survivors_finished_runs: int
    survivors_share: float | None
    survivors_ci_low: float | None
    survivors_ci_high: float | None
    sending_runs: int


MEANS_KEYS = tuple(f.name for f in fields(MiddlewareMeans))


def middleware_of(run: FinishedRun) -> str:
    """The run's middleware: result.json's `messaging`, else its config (older: nanomsg)."""
    name = (run.messaging or {}).get("middleware")
    if not name:
        return run.config.middleware
    return name if isinstance(name, str) else DEFAULT_MIDDLEWARE


def failure_of(run: FinishedRun) -> str:
    """The run's battery failure (`none` for runs made before the option)."""
    return run.config.battery_failure


def main_messaging(runs: list[FinishedRun]) -> tuple[str, str]:
    """(middleware, failure) the paper's figures are drawn for when a sweep varied them:
    the default middleware without a failure where it ran."""
    present = {(middleware_of(r), failure_of(r)) for r in runs if r.usable}
    main = (DEFAULT_MIDDLEWARE, NONE)
    return main if main in present or not present else min(present)


def _number(x) -> float | None:
    return float(x) if isinstance(x, int | float) and not isinstance(x, bool) else None


def _air(run: FinishedRun, metrics: RoutingMetrics | None) -> tuple[float | None, float | None]:
    """(bytes per robot per robot-second, own share) of the middleware's captured traffic;
    (None, None) where the captures have no class for it."""
    mw = (metrics.middleware if metrics else None) or MiddlewareTraffic()
    tx, own = _number(mw.tx_bytes), _number(mw.protocol_bytes)
    if tx is None:
        return None, None
    wall = _number(metrics.duration_s) if metrics else None
    per_robot_s = run.per_robot_second(tx, wall, run.config.robots)
    return per_robot_s, (own / tx if own is not None and tx else None)


def run_row(run: FinishedRun, metrics: RoutingMetrics | None) -> MiddlewareRun:
    """One run's numbers (`metrics`: its routing.json, or None without captures)."""
    team = (run.messaging or {}).get("team") or {}
    sent, received = _number(team.get("sent")), _number(team.get("received"))
    counted, wall = _number(team.get("robots")), _number(run.step_loop_wall_s)
    blocked = _number(team.get("blocked_s"))
    air, own = _air(run, metrics)
    survived = run.survivors_finished
    return MiddlewareRun(
        run=run.run_id,
        middleware=middleware_of(run),
        battery_failure=failure_of(run),
        comm_range=run.config.comm_range,
        robots=run.config.robots,
        steps=run.exploration_steps,
        survivors_finished=None if survived is None else int(survived),
        delivery=received / sent if sent and received is not None else None,
        failed=_number(team.get("failed")),
        duplicates=_number(team.get("duplicates")),
        late=_number(team.get("late")),
        blocked_share=blocked / (counted * wall)
        if blocked is not None and counted and wall
        else None,
        blocked_max_s=_number(team.get("blocked_max_s")),
        sending=_number(team.get("sending")),
        air_bytes_per_robot_s=air,
        air_own_share=own,
    )


def _sort_key(key: tuple) -> tuple:
    robots, comm, failure, mw = key
    return (robots, comm, _index(FAILURE_ORDER, failure), _index(MIDDLEWARES, mw), mw)


def _index(order: tuple, value) -> int:
    return order.index(value) if value in order else len(order)


PointKey = tuple[int, float, str, str]  # (robots, comm_range, battery_failure, middleware)


def point_rows(
    per_run: list[MiddlewareRun], left_out: dict[PointKey, int] | None = None
) -> list[MiddlewarePoint]:
    """Per (team, range, failure, middleware): each of MEANS with its 95% interval
    (`KEY_ci_low`, `KEY_ci_high`; None for fewer than two values), the survivors' share
    with its Wilson interval, and `left_out`, the point's runs the report did not count."""
    groups: dict[PointKey, list[MiddlewareRun]] = {}
    for r in per_run:
        key = (r.robots, r.comm_range, r.battery_failure, r.middleware)
        groups.setdefault(key, []).append(r)
    for key in left_out or {}:
        groups.setdefault(key, [])
    out = []
    for key, items in sorted(groups.items(), key=lambda kv: _sort_key(kv[0])):
        means = {
            k: MeanCI.of([v for i in items if (v := getattr(i, k)) is not None]) for k in MEANS_KEYS
        }
        judged = [i.survivors_finished for i in items if i.survivors_finished is not None]
        share = stats.share_ci(sum(judged), len(judged))
        out.append(MiddlewarePoint(
            *key, n=len(items), left_out=(left_out or {}).get(key, 0),
            means=MiddlewareMeans(**means),
            survivors_runs=len(judged), survivors_finished_runs=sum(judged),
            survivors_share=share[0] if share else None,
            survivors_ci_low=share[1] if share else None,
            survivors_ci_high=share[2] if share else None,
            sending_runs=sum(1 for i in items if i.sending),
        ))  # fmt: skip
    return out


def tables(
    runs: list[FinishedRun], metrics: Mapping[str, RoutingMetrics | None]
) -> tuple[list[MiddlewareRun], list[MiddlewarePoint]]:
    """(per-run rows of the usable runs, point rows) of a sweep's runs; `metrics`: each run
    id's pcapmetrics (or None)."""
    per_run = [run_row(r, metrics.get(r.run_id)) for r in runs if r.usable]
    left: dict[PointKey, int] = {}
    for r in runs:
        if not r.usable:
            key = (r.config.robots, r.config.comm_range, failure_of(r), middleware_of(r))
            left[key] = left.get(key, 0) + 1
    return per_run, point_rows(per_run, left)


# ---------------------------------------------------------------- the verdict


def pooled(rows: list[MiddlewarePoint]) -> dict[str, dict[str, tuple[int, int]]]:
    """{middleware: {failure: (runs whose survivors finished, runs)}} over the points (team,
    range) that ran the middleware both without and with the failure."""
    by: dict[tuple, dict[str, MiddlewarePoint]] = {}
    for r in rows:
        by.setdefault((r.middleware, r.robots, r.comm_range), {})[r.battery_failure] = r
    out: dict[str, dict[str, list[int]]] = {}
    for (mw, _, _), modes in by.items():
        if not all(f in modes for f in FAILURE_ORDER):
            continue
        acc = out.setdefault(mw, {f: [0, 0] for f in FAILURE_ORDER})
        for f in FAILURE_ORDER:
            acc[f][0] += modes[f].survivors_finished_runs
            acc[f][1] += modes[f].survivors_runs
    return {mw: {f: (v[0], v[1]) for f, v in acc.items()} for mw, acc in out.items()}


def _share_text(hits: int, n: int) -> str:
    ci = stats.share_ci(hits, n)
    if ci is None:
        return "no runs"
    return f"{hits} of {n} ({ci[0]:.0%}, 95% interval {ci[1]:.0%}-{ci[2]:.0%})"


def middleware_verdict(without: tuple[int, int], failed: tuple[int, int]) -> tuple[str, str]:
    """The rule for one middleware: (verdict, why) from (finished, runs) without the failure
    and with it."""
    text = f"survivors finished without the failure {_share_text(*without)}, with one robot "
    text += f"killed at mid-run {_share_text(*failed)}"
    if without[1] < MIN_RUNS or failed[1] < MIN_RUNS:
        return TOO_FEW, text + f" (fewer than {MIN_RUNS} runs in a mode)"
    n, f = stats.share_ci(*without), stats.share_ci(*failed)
    assert n is not None and f is not None  # runs in both modes (MIN_RUNS)
    if n[0] < FINISH_WITHOUT_MIN:
        return UNDECIDED, text + " (the team does not finish reliably even without the failure)"
    if f[0] < STOP_WITH_MAX and stats.separated(n, f):
        return HOLDS, text + ": the team stops"
    if f[0] >= FINISH_WITHOUT_MIN:
        return FAILS, text + ": the team carries on"
    return UNDECIDED, text + " (between the rule's bounds, or within the noise)"


def paper_verdict(by_middleware: dict[str, tuple[str, str]]) -> tuple[str, str]:
    """The paper's reading from the middlewares' verdicts: (verdict, why)."""
    naive = by_middleware.get(NAIVE, (None, ""))[0]
    bounded = {m: by_middleware[m][0] for m in BOUNDED if m in by_middleware}
    if naive is None or not bounded:
        return (
            UNDECIDED,
            f"needs {NAIVE} and a bounded-send middleware, with and without the failure",
        )
    stopped = [m for m, v in bounded.items() if v == HOLDS]
    if naive == FAILS:
        return FAILS, f"{NAIVE} did not stop the team"
    if stopped:
        return FAILS, f"a bounded-send middleware stopped the team: {', '.join(stopped)}"
    if naive == HOLDS and all(v == FAILS for v in bounded.values()):
        return HOLDS, f"{NAIVE} stopped the team, and none of {', '.join(bounded)} did"
    open_ = [m for m, v in {NAIVE: naive, **bounded}.items() if v in (TOO_FEW, UNDECIDED)]
    worst = TOO_FEW if any(by_middleware[m][0] == TOO_FEW for m in open_) else UNDECIDED
    return worst, f"not decided for {', '.join(open_)}"


def verdicts(rows: list[MiddlewarePoint]) -> tuple[dict[str, tuple[str, str]], tuple[str, str]]:
    """({middleware: (verdict, why)}, the paper's reading) of a sweep's point rows."""
    pools = pooled(rows)
    by = {m: middleware_verdict(p[NONE], p[MIDRUN]) for m, p in pools.items()}
    by = dict(sorted(by.items(), key=lambda kv: _index(MIDDLEWARES, kv[0])))
    return by, paper_verdict(by)


# ---------------------------------------------------------------- the section


def _cell(row: MiddlewarePoint, key: str, spec: str) -> str:
    m = row.means.of(key)
    if m.mean is None:
        return "not measured" if key.startswith("air_") else "–"
    if m.ci_low is None:
        return format(m.mean, spec)
    return (f"{format(m.mean, spec)} [{format(m.ci_low, spec)}, "
            f"{format(m.ci_high, spec)}]")  # fmt: skip


def _survivors(row: MiddlewarePoint) -> str:
    if not row.survivors_runs:
        return "–"
    return f"{row.survivors_finished_runs} of {row.survivors_runs}"


def section(rows: list[MiddlewarePoint]) -> list[str]:
    """The report's "Which middleware a team can rely on" section (empty unless the sweep
    ran more than one middleware)."""
    if len({r.middleware for r in rows}) < 2:
        return []
    out = ["## Which middleware a team can rely on (the paper's Section 3)", ""]
    out += [
        f'The paper chose nanomsg over ZeroMQ because "{PAPER_CLAIM}". Each point ran every '
        "middleware, without a failure and with one robot (the highest-numbered) killed at "
        "mid-run (`--battery-failure midrun`, docs/middleware.md), on the same seeds. Every "
        "cell: the mean over the point's runs with its 95% interval in brackets (Student t). "
        "Steps: the mean finishing step of the robots not stopped (a survivor that never "
        "finished counts the step cap). Survivors finished: in how many runs every robot not "
        "killed finished. Delivery and the send counts: the messengers' own counters "
        "(result.json `messaging`; the killed robot leaves none, so with the failure what it "
        "received is missing and delivery reads low). Blocked: the team's wall seconds "
        "inside a send per robot-second of wall time, and the longest send; runs that ended "
        "with a send still waiting are counted. Air: the middleware's bytes on the wire per "
        "robot per second of robot time, and its own share of them (framing, greetings, "
        'replies), from the captures; "not measured" where the captures have no class for '
        "the middleware. Left out: runs the report did not count (not complete or step cap, "
        "or not faithful to their time scale). The paper's figures and verdicts above are "
        f"drawn from the {DEFAULT_MIDDLEWARE} runs without a failure alone.",
        "",
        "| robots | range (m) | failure | middleware | runs | left out | survivors finished | "
        + " | ".join(name for _, name, _ in MEANS)
        + " | sends still waiting |",
        "|---|---|---|---|---|---|---|" + "---|" * len(MEANS) + "---|",
    ]
    for r in rows:
        cells = " | ".join(_cell(r, k, spec) for k, _, spec in MEANS)
        out.append(
            f"| {r.robots} | {r.comm_range:g} | {r.battery_failure} | "
            f"{r.middleware} | {r.n} | {r.left_out} | {_survivors(r)} | {cells} | "
            f"{r.sending_runs} of {r.n} |"
        )
    out += ["", f"**Rule.** {VERDICT_RULE}", ""]
    by, (paper, why) = verdicts(rows)
    if not by:
        return out + ["No middleware ran both with and without the failure: no verdict.", ""]
    out += [f"**Does the paper's claim hold?** {paper}: {why}.", ""]
    out += [f"- {m}: {v}; {text}." for m, (v, text) in by.items()]
    if any(r.left_out for r in rows):
        out += [
            "",
            "Runs left out are not in the verdict; a send that blocks the planner also makes "
            "plans late, which the fidelity verdict counts, so look at them with "
            "`testbed report --include-unfaithful` before reading a stop as not measured.",
        ]
    return out + [""]
