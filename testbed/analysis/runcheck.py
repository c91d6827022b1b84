"""Checks of a finished run's directory against its own link timeline.

`causality_violations` replays links.csv and asks, for every message a robot logged as
received (map floods, goals, re-plan requests), whether a time-respecting multi-hop path from
its sender existed between the step it was sent and the step it was received: starting from
the sender at the send step, the set of robots the message could have reached grows, step by
step, by the connected components of that step's links. A message that arrived anyway came
around the emulated network (or through a bug), which is what the check is for.

Steps in the logs are the robots' own steps (the last frame each had processed), which lag
the world's when a robot falls behind. Where the run wrote clock.csv (when each step began,
on the CLOCK_MONOTONIC that receipts are logged with as "t"), a receipt's window ends at the
world's step at that moment; `slack` widens the window by a step or two on each side.
"""

from __future__ import annotations

import bisect
import csv
from collections import defaultdict

from node import events
from testbed.files import csvfiles, layout
from testbed.files.resultfile import RunResult


def link_timeline(out: str) -> dict[int, list[tuple[str, int, int]]]:
    changes: dict[int, list[tuple[str, int, int]]] = defaultdict(list)
    for c in csvfiles.read_links(out):
        changes[c.step].append(("add" if c.added else "remove", c.i, c.j))
    return changes


def links_by_step(out: str, last_step: int) -> list[set[tuple[int, int]]]:
    """The link set in force during each step 0..last_step."""
    changes = link_timeline(out)
    current: set[tuple[int, int]] = set()
    out_sets = []
    for step in range(last_step + 1):
        for ev, i, j in changes.get(step, []):
            if ev == "add":
                current.add((i, j))
            else:
                current.discard((i, j))
        out_sets.append(set(current))
    return out_sets


def _grow(reached: set[int], links: set[tuple[int, int]]) -> set[int]:
    adj: dict[int, list[int]] = defaultdict(list)
    for i, j in links:
        adj[i].append(j)
        adj[j].append(i)
    stack = list(reached)
    seen = set(reached)
    while stack:
        v = stack.pop()
        for w in adj[v]:
            if w not in seen:
                seen.add(w)
                stack.append(w)
    return seen


def received(out: str, robots: int) -> list[dict]:
    """Every 'recv' event of every robot, with "to" added."""
    evs = []
    for k in range(1, robots + 1):
        path = layout.robot_events(out, k)
        evs += [{**e.to_dict(), "to": k} for e in events.read(path, only=("recv",))]
    return evs


def step_clock(out: str) -> list[float]:
    """When each step began (clock.csv), or [] for runs without it."""
    try:
        with open(layout.clock_path(out)) as f:
            return [float(row["t"]) for row in csv.DictReader(f)]
    except (OSError, KeyError, ValueError):
        return []


def causality_violations(out: str, slack: int = 2) -> tuple[int, list[dict]]:
    """(messages checked, messages that had no time-respecting path from their sender)."""
    result = RunResult.from_json(out)
    robots, steps = result.config.robots, int(result.steps or 0)  # (None: it never stepped)
    sets = links_by_step(out, steps + slack + 1)
    evs = received(out, robots)
    clock = step_clock(out)
    bad = []
    for e in evs:
        start = max(0, e["sent"] - slack)
        at = e["step"]
        if clock and "t" in e:  # the world's step when the robot logged the receipt
            at = max(at, bisect.bisect_right(clock, e["t"]) - 1)
        end = min(len(sets) - 1, max(at, start) + slack)
        reached = {e["frm"]}
        for t in range(start, end + 1):
            reached = _grow(reached, sets[t])
            if e["to"] in reached:
                break
        if e["to"] not in reached:
            bad.append(e)
    return len(evs), bad


def heard_from(out: str, robots: int, kind: str = "map") -> dict[int, set[int]]:
    """For each robot, the robots it received at least one `kind` message from."""
    got: dict[int, set[int]] = {k: set() for k in range(1, robots + 1)}
    for e in received(out, robots):
        if e["kind"] == kind:
            got[e["to"]].add(e["frm"])
    return got
