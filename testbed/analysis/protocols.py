"""Routing protocols compared on the same exploration workload, against the oracle.

Theory of operation
-------------------
A protocols sweep (testbed/experiments/protocols.toml) runs every point of its grid once per
routing (aodv, babel, batman, oracle) on the same seeds. Per run (`run_row`): exploration
steps (as Fig. 2), routing overhead from the captures (control packets and bytes per robot
per second of robot time, i.e. wall seconds x time scale), packet delivery fraction and
median end-to-end delay of the robots' TCP traffic (wall clock), the share of map floods
that reached each teammate, and, for AODV, the median route-discovery latency its daemons
measured. `point_rows` averages them per (map, medium, range, team, routing), steps with
their 95% interval (a sweep that also varied the medium compares protocols within each);
`section` sets each protocol beside the oracle, point by point, and says whether the paper's
choice holds, by the rule in `CHOICE_RULE` (fixed before any sweep was run).
"""

from __future__ import annotations

import statistics
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path

from aodv.statsfile import DaemonStats, StatsError, run_stats_files
from testbed.analysis import stats
from testbed.analysis.rows import INLINE, Measures
from testbed.analysis.runs import FinishedRun
from testbed.files.routingfile import RoutingMetrics
from topology.protocols import REGISTRY
from topology.spec import ROUTINGS, VETH

# The proactive protocols, which the rule sets against AODV (topology.protocols).
PROACTIVE = tuple(p.name for p in REGISTRY.values() if p.proactive)
# How far the AODV control packets counted in the captures may be from the daemons' own
# counters and still agree (here and in the report's check of every run).
DAEMON_AGREEMENT = 0.01
CHOICE_RULE = (
    "The paper's choice (AODV for a small robot team) holds at a point when AODV sends fewer "
    "control packets per robot per second than each proactive protocol that ran there, and "
    "its exploration steps are not worse than theirs beyond noise (AODV's 95% interval is "
    "below theirs or overlaps it). It fails at a point when a proactive protocol needs "
    "fewer steps beyond noise, or sends fewer control packets."
)


@dataclass(frozen=True)
class ProtocolMeasures(Measures):
    """What the comparison measures of a run, or averages over a point's runs (METRICS)."""

    steps: float | None
    control_pkts_per_robot_s: float | None
    control_bytes_per_robot_s: float | None
    pdf: float | None
    delay_ms: float | None
    map_delivery: float | None
    discovery_ms: float | None


# The measures, by name (the report and the rule reach them so).
METRICS = tuple(f.name for f in fields(ProtocolMeasures))


@dataclass(frozen=True)
class ProtocolRun:
    """One run's numbers for the protocols comparison."""

    run: str
    routing: str
    map: str
    medium: str
    comm_range: float
    robots: int
    measures: ProtocolMeasures = field(metadata=INLINE)
    # AODV: captured control packets against its daemons' own counts (pcapmetrics).
    daemon_difference: float | None = None


@dataclass(frozen=True)
class ProtocolPoint:
    """Per (map, medium, range, team, routing): each of METRICS's mean over the runs, and
    the 95% interval of the steps' mean."""

    map: str
    medium: str
    comm_range: float
    robots: int
    routing: str
    n: int
    daemon_difference_max: float | None
    measures: ProtocolMeasures = field(metadata=INLINE)
    steps_ci_low: float | None = None
    steps_ci_high: float | None = None

    @property
    def steps_ci(self) -> tuple[float, float, float] | None:
        """(mean, low, high) of the steps, None without an interval."""
        steps = self.measures.steps
        if steps is None or self.steps_ci_low is None or self.steps_ci_high is None:
            return None
        return steps, self.steps_ci_low, self.steps_ci_high

    def measure(self, key: str) -> float | None:
        """One of METRICS, by name."""
        return self.measures.of(key)


def _map_delivery(run: FinishedRun) -> float | None:
    """Mean over robots (but those stopped on purpose) of (map floods it received) / (map
    floods its teammates sent)."""
    sent = {r.name: r.sent.get("map", 0) for r in run.robots}
    total = sum(sent.values())
    shares = []
    for r in run.counted_robots:
        others = total - sent[r.name]
        if others:
            shares.append(min(1.0, r.received.get("map", 0) / others))
    return statistics.fmean(shares) if shares else None


def _discovery_ms(run_dir: Path) -> float | None:
    """Median latency of the successful route discoveries of the run's AODV daemons."""
    lat = []
    for p in run_stats_files(run_dir) or []:
        try:
            lat += [1000 * s for s in DaemonStats.read(p).discovery_latencies_s]
        except StatsError:
            continue
    return statistics.median(lat) if lat else None


def run_row(run: FinishedRun, steps: float | None, metrics: RoutingMetrics | None) -> ProtocolRun:
    """One run's numbers (`metrics`: its routing.json, or None)."""
    c = run.config
    m = metrics or RoutingMetrics()
    return ProtocolRun(
        run=run.run_id,
        routing=c.routing,
        map=c.map_name,
        medium=c.medium,
        comm_range=c.comm_range,
        robots=c.robots,
        measures=ProtocolMeasures(
            steps=steps,
            control_pkts_per_robot_s=run.captured_per_robot_s(m, "control_tx_packets"),
            control_bytes_per_robot_s=run.captured_per_robot_s(m, "control_tx_bytes"),
            pdf=m.pdf,
            delay_ms=m.delay_ms_median,
            map_delivery=_map_delivery(run),
            discovery_ms=_discovery_ms(run.path),
        ),
        daemon_difference=m.daemon_comparison.relative_difference if m.daemon_comparison else None,
    )


def point_rows(per_run: list[ProtocolRun]) -> list[ProtocolPoint]:
    """Per (map, medium, range, team, routing): each metric's mean; steps with their 95%
    interval."""
    groups: dict[tuple[str, str, float, int, str], list[ProtocolRun]] = {}
    for r in per_run:
        key = (r.map, r.medium, r.comm_range, r.robots, r.routing)
        groups.setdefault(key, []).append(r)
    out = []
    order = {p: i for i, p in enumerate(ROUTINGS)}  # protocols in the order of the choices
    for key, items in sorted(groups.items(), key=lambda kv: (*kv[0][:4], order.get(kv[0][4], 9))):
        diffs = [i.daemon_difference for i in items if i.daemon_difference is not None]
        means = {}
        for m in METRICS:
            vals = [v for i in items if (v := getattr(i.measures, m)) is not None]
            means[m] = statistics.fmean(vals) if vals else None
        ci = stats.mean_ci([x for i in items if (x := i.measures.steps) is not None])
        mp, medium, comm, robots, routing = key
        out.append(ProtocolPoint(
            map=mp, medium=medium, comm_range=comm, robots=robots, routing=routing,
            n=len(items), daemon_difference_max=max(diffs) if diffs else None,
            measures=ProtocolMeasures(**means),
            steps_ci_low=ci[1] if ci else None, steps_ci_high=ci[2] if ci else None,
        ))  # fmt: skip
    return out


def tables(
    runs: list[FinishedRun], metrics: Mapping[str, RoutingMetrics | None]
) -> tuple[list[ProtocolRun], list[ProtocolPoint]]:
    """(per-run rows of the usable runs, point rows) of a sweep's runs; `metrics`: each run
    id's pcapmetrics (or None)."""
    per_run = [run_row(r, r.exploration_steps, metrics.get(r.run_id)) for r in runs if r.usable]
    return per_run, point_rows(per_run)


def choice_holds(point: dict[str, ProtocolPoint]) -> tuple[bool | None, str]:
    """CHOICE_RULE at one point ({routing: row}); None when AODV or no proactive protocol ran."""
    a = point.get("aodv")
    rivals = [point[p] for p in PROACTIVE if p in point]
    if a is None or not rivals:
        return None, "needs AODV and a proactive protocol"
    reasons, unknown = [], False
    for r in rivals:
        ca, cr = a.measures.control_pkts_per_robot_s, r.measures.control_pkts_per_robot_s
        if ca is not None and cr is not None and ca >= cr:
            reasons.append(f"{r.routing} sends fewer control packets ({cr:.2f} vs {ca:.2f})")
        ia, ir = a.steps_ci, r.steps_ci
        unknown = unknown or not (ia and ir)
        if ia and ir and stats.separated(ia, ir) and ir[0] < ia[0]:
            reasons.append(
                f"{r.routing} needs fewer steps beyond noise ({ir[0]:.0f} vs {ia[0]:.0f})"
            )
    if reasons:
        return False, "; ".join(reasons)
    if unknown:
        return True, "fewer control packets; steps not comparable (one run: noise unknown)"
    return True, "fewer control packets, steps within noise"


# Other measures than the rule's, counted beside it (not part of the verdict): (metric,
# whether AODV must be below (-1) or above (+1) each proactive protocol, what it says).
BESIDE_THE_RULE = (
    ("control_bytes_per_robot_s", -1, "sends fewer control bytes per robot per second"),
    ("pdf", +1, "delivers a larger share of the robots' TCP packets"),
)


def beside_the_rule(points: list[dict[str, ProtocolPoint]]) -> list[str]:
    """At how many points AODV beats every proactive protocol on each BESIDE_THE_RULE
    measure (points where AODV or no proactive protocol ran, or a value is missing, are not
    counted)."""
    out = []
    for key, sign, says in BESIDE_THE_RULE:
        wins = total = 0
        for by in points:
            a, rivals = by.get("aodv"), [by[p] for p in PROACTIVE if p in by]
            ours = a.measure(key) if a else None
            theirs = [r.measure(key) for r in rivals]
            if not rivals or ours is None or any(v is None for v in theirs):
                continue
            total += 1
            wins += all(sign * (ours - v) > 0 for v in theirs if v is not None)
        if total:
            out.append(f"- AODV {says} than each proactive protocol at {wins} of {total} points.")
    return out


def _control_check(rows: list[ProtocolPoint]) -> list[str]:
    """Is each protocol's captured control traffic what its daemons sent?"""
    lines = []
    aodv = [r.daemon_difference_max for r in rows if r.routing == "aodv"]
    checked = [d for d in aodv if d is not None]
    if checked:
        lines.append(
            f"- AODV: at {sum(d <= DAEMON_AGREEMENT for d in checked)} of {len(checked)} "
            f"points the captured control packets are within {DAEMON_AGREEMENT:.0%} of what "
            f"its daemons counted sending (largest difference {max(checked):.2%})."
        )
    for p in PROACTIVE:
        if any(r.routing == p for r in rows):
            lines.append(
                f"- {p}: its daemon keeps no count of what it sends, so its captured control "
                "traffic cannot be checked against the daemon; it is counted on its port "
                f"(UDP {REGISTRY[p].control_port}) at each transmitter."
            )
    oracle = [
        x
        for r in rows
        if r.routing == "oracle" and (x := r.measures.control_pkts_per_robot_s) is not None
    ]
    if oracle:
        lines.append(
            "- oracle: no control packet in its captures, as there must be none."
            if not any(oracle)
            else f"- oracle: its captures hold up to {max(oracle):.2f} packets per robot per "
            f"second on UDP {REGISTRY['oracle'].control_port}, which nothing of the oracle "
            "sends: check the runs."
        )
    return ["Control traffic in the captures against what the protocols sent:", "", *lines]


def _fmt(x, spec: str) -> str:
    return "–" if x is None else format(x, spec)


def _steps(row: ProtocolPoint) -> str:
    steps = row.measures.steps
    if steps is None:
        return "–"
    if row.steps_ci_low is None:
        return f"{steps:.0f}"
    return f"{steps:.0f} [{row.steps_ci_low:.0f}, {row.steps_ci_high:.0f}]"


def _vs(x, base, ratio: bool = True) -> str:
    if x is None or base is None:
        return ""
    if ratio:
        return f" ({x / base:.2f}x)" if base else ""
    return f" ({x - base:+.2f})"


def section(rows: list[ProtocolPoint]) -> list[str]:
    """The report's "Routing protocols" section (empty if the sweep ran one routing)."""
    if len({r.routing for r in rows}) < 2:
        return []
    out = ["## Routing protocols against the oracle", ""]
    out += [
        "Each point ran every protocol on the same seeds. Steps: mean with its 95% interval "
        "(Student t); control traffic per robot per second of robot time, from the captures; "
        "PDF and delay of the robots' TCP traffic (delay in wall-clock ms); map floods: the "
        "share of teammates' map floods each robot received; discovery: the median AODV "
        "route discovery its daemons measured. In brackets, against the oracle at the same "
        "point (steps and delay as ratios, PDF and map floods as differences); the oracle "
        "sends no control packet, so overhead is shown as is.",
        "",
        "| map | range (m) | robots | routing | runs | steps [95% CI] | ctl pkts/robot/s | "
        "ctl bytes/robot/s | PDF | delay (ms) | map floods | discovery (ms) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    points: dict[tuple, dict[str, ProtocolPoint]] = {}
    for r in rows:
        points.setdefault((_where(r), r.comm_range, r.robots), {})[r.routing] = r
    out += _table_rows(points)
    out += [""] + _control_check(rows) + ["", f"**Rule.** {CHOICE_RULE}", ""]
    return out + _choice_lines(points)


def _where(row: ProtocolPoint) -> str:
    """The map column: the map, and the medium when it is not veth (a media sweep)."""
    return row.map if row.medium == VETH else f"{row.map} ({row.medium})"


def _table_rows(points: dict[tuple, dict[str, ProtocolPoint]]) -> list[str]:
    """One table row per (point, protocol), each beside the oracle at the same point."""
    out = []
    for (mp, comm, robots), by in points.items():
        o = by.get("oracle")
        for r in by.values():
            m = r.measures
            out.append(
                f"| {mp} | {comm:g} | {robots} | {r.routing} | {r.n} | {_steps(r)}"
                f"{_beside(r, o, 'steps')} | "
                f"{_fmt(m.control_pkts_per_robot_s, '.2f')} | "
                f"{_fmt(m.control_bytes_per_robot_s, '.0f')} | {_fmt(m.pdf, '.3f')}"
                f"{_beside(r, o, 'pdf', False)} | "
                f"{_fmt(m.delay_ms, '.2f')}"
                f"{_beside(r, o, 'delay_ms')} | "
                f"{_fmt(m.map_delivery, '.3f')}"
                f"{_beside(r, o, 'map_delivery', False)} | "
                f"{_fmt(m.discovery_ms, '.1f')} |"
            )
    return out


def _beside(r: ProtocolPoint, oracle: ProtocolPoint | None, key: str, ratio: bool = True) -> str:
    """A measure against the oracle's at the same point (nothing for the oracle itself)."""
    if r.routing == "oracle":
        return ""
    return _vs(r.measure(key), oracle.measure(key) if oracle else None, ratio)


def _choice_lines(points: dict[tuple, dict[str, ProtocolPoint]]) -> list[str]:
    """Whether the paper's choice holds, point by point, and the measures beside the rule."""
    out = []
    verdicts = [(key, *choice_holds(by)) for key, by in points.items()]
    judged = [(k, ok, why) for k, ok, why in verdicts if ok is not None]
    held = sum(ok for _, ok, _ in judged)
    if not judged:
        out += ["No point ran both AODV and a proactive protocol: the rule cannot be applied.", ""]
        return out
    out += [
        f"**Does the paper's choice hold?** At {held} of {len(judged)} points"
        + (" (all)." if held == len(judged) else "; where not:"),
        "",
    ]
    blind = [k for k, ok, why in judged if ok and "noise unknown" in why]
    if blind:
        out += [
            f"At {len(blind)} of them the steps rest on one run per protocol, so only the "
            "control traffic decided: run more runs per point to test the steps too.",
            "",
        ]
    for (mp, comm, robots), ok, why in judged:
        if not ok:
            out.append(f"- {mp} map, {comm:g} m, {robots} robots: {why}.")
    beside = beside_the_rule(list(points.values()))
    if beside:
        out += ["", "Beside the rule (other measures, not part of the verdict):", "", *beside]
    out.append("")
    return out
