"""`testbed compare DIR_A DIR_B`'s claims: the paper's claims as each sweep decides them, side
by side, and whether the two agree.

Theory of operation. Two deciding sweeps (say the paper's grid run twice with different
seeds, each followed by its stage 2: docs/guide.md, "Deciding the paper's claims") should
reach the same verdicts; two plain sweeps show how far 3 runs a point carry. For each sweep
`claims_of` reads:

- the report's verdicts on its runs (testbed.analysis.verdicts, on the same runs and points
  as `testbed report`: the main network, messaging and variant; runs not faithful to their
  time scale left out unless asked for), the paper's 3 runs a point;
- its deciding verdicts, when it has a plan directory beside it (SWEEP_DIR-stage2 with a
  plan.json, as the report finds it; testbed.analysis.decidesweep.load_decided), each
  claim's and each comparison's final verdict. A plan directory that cannot be read is
  named, and that sweep has no deciding verdicts.

`section` sets them side by side: per claim the two verdicts and whether they agree
(compared as holds, does not hold, partly holds, undecided: testbed.analysis.decidereport's
`category`): "yes", "one undecided" (a verdict on one side, none on the other: the budget or
the power fell short, not a contradiction) or **no** (two different verdicts), with the
comparisons both sweeps made and how many of those agree; then one sentence per kind of
verdict: on how many claims the sweeps agree, where one is undecided, where they disagree.
The deciding verdicts are compared only when both sweeps have them. Two sweeps of the same
directory name are told apart by their paths.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from common.errors import UsageError
from testbed.analysis import decide, decidereport, decidesweep, middlewares, tables, verdicts
from testbed.analysis.figures import Tables
from testbed.analysis.runs import FinishedRun, load_runs
from testbed.files.resultvalues import one_line


@dataclass
class SweepClaims:
    """One sweep's verdicts: the report's (claim -> verdict) and, with a stage 2, the
    deciding ones (decide's claim key -> verdict, and -> {comparison: final verdict})."""

    name: str
    path: str
    three_run: dict[str, str] = field(default_factory=dict)
    decided: dict[str, str] | None = None
    comparisons: dict[str, dict[str, str]] = field(default_factory=dict)
    note: str = ""  # why it has no deciding verdicts, or that its stage 2 is unfinished


def report_verdicts(runs: list[FinishedRun]) -> list[verdicts.Verdict]:
    """The report's verdicts on a sweep's runs, on the points `testbed report` takes."""
    network = tables.main_network(runs)
    messaging = middlewares.main_messaging(runs)
    runs = [r for r in runs if r.network == network
            and (middlewares.middleware_of(r), middlewares.failure_of(r)) == messaging]  # fmt: skip
    main = tables.main_variant(runs)
    fig2 = [r for r in tables.fig2_rows(runs) if r.variant == main]
    plans = [r for r in tables.plan_cause_rows(runs) if r.variant == main]
    return verdicts.verdicts(Tables(fig2=fig2, plans=plans))


def claims_of(sweep_dir: str | Path, unfaithful: bool = False) -> SweepClaims:
    sweep_dir = Path(sweep_dir)
    out = SweepClaims(sweep_dir.name, str(sweep_dir))
    runs = load_runs(sweep_dir, unfaithful)
    out.three_run = {v.claim: v.verdict for v in report_verdicts(runs)}
    plan_dir = decidesweep.find_plan(sweep_dir)
    if plan_dir is None:
        out.note = "no stage 2 (no plan directory beside it)"
        return out
    try:
        d = decidesweep.load_decided(plan_dir)
    except (UsageError, ValueError, OSError) as e:
        out.note = f"its stage 2 was not read: {one_line(str(e))}"
        return out
    if decidereport.not_run(d):
        out.note = f"its stage 2 has not run ({d.plan.total_runs} runs planned)"
        return out
    doc = decidereport.decided_doc(d)
    out.decided = {k: c["verdict"] for k, c in doc["claims"].items()}
    out.comparisons = {k: c["comparisons"] for k, c in doc["claims"].items()}
    if d.done_runs < d.plan.total_runs:
        out.note = f"stage 2 unfinished: {d.done_runs} of {d.plan.total_runs} runs"
    return out


def agreement(a: str, b: str) -> str:
    """ "yes", "one undecided" or "**no**" (see the module docstring)."""
    ca, cb = decidereport.category(a), decidereport.category(b)
    if ca == cb:
        return "yes"
    return "one undecided" if decidereport.UNDECIDED in (ca, cb) else "**no**"


def _comparisons(a: Mapping[str, str], b: Mapping[str, str]) -> str:
    """How many comparisons both sweeps made agree (the rise's pair may differ)."""
    common = sorted(set(a) & set(b))
    same = sum(a[w] == b[w] for w in common)
    return f"{same} of {len(common)}" if common else "none in common"


def _sentence(kind: str, rows: list[tuple[str, str, str]], names: tuple[str, str]) -> str:
    if not rows:
        return f"- {kind}: none to compare."
    said = [(agreement(x, y), c, x, y) for c, x, y in rows]
    same = sum(a == "yes" for a, *_ in said)
    text = f"- {kind}: the two sweeps agree on {same} of {len(rows)} claims"
    for word, head in (("one undecided", "one is undecided on"), ("**no**", "they disagree on")):
        off = [f"{c} ({names[0]}: {x}, {names[1]}: {y})" for a, c, x, y in said if a == word]
        if off:
            text += f"; {head} " + "; ".join(off)
    return text + "."


def section(a: SweepClaims, b: SweepClaims) -> list[str]:
    """Markdown: the claims' verdicts in both sweeps and whether they agree."""
    names = (a.name, b.name) if a.name != b.name else (a.path, b.path)
    out = ["## The paper's claims in both sweeps", ""]
    deciding: list[tuple[str, str, str]] = []
    if a.decided is not None and b.decided is not None:
        out += [f"Deciding verdicts (stage 1 and stage 2, {decide.TEST}, Holm per claim, "
                "error rate per claim as each plan states):", "",
                f"| Claim | {names[0]} | {names[1]} | Agree | Comparisons agreeing |",
                "|---|---|---|---|---|"]  # fmt: skip
        for key, text in decide.CLAIMS.items():
            if key in a.decided and key in b.decided:
                x, y = a.decided[key], b.decided[key]
                deciding.append((text, x, y))
                out.append(f"| {text} | {x} | {y} | {agreement(x, y)} | "
                           f"{_comparisons(a.comparisons[key], b.comparisons[key])} |")  # fmt: skip
        out.append("")
    out += ["The report's verdicts (3 runs a point, or whatever each sweep ran):", "",
            f"| Claim | {names[0]} | {names[1]} | Agree |", "|---|---|---|---|"]  # fmt: skip
    plain = []
    for claim, x in a.three_run.items():
        if claim in b.three_run:
            y = b.three_run[claim]
            plain.append((claim, x, y))
            out.append(f"| {claim} | {x} | {y} | {agreement(x, y)} |")
    out.append("")
    if deciding:
        out.append(_sentence("Deciding verdicts", deciding, names))
    else:
        why = [f"{s.name}: {s.note}" for s in (a, b) if s.decided is None]
        out.append(f"- Deciding verdicts: not compared ({'; '.join(why)}).")
    out.append(_sentence("The report's verdicts", plain, names))
    notes = [f"{s.name}: {s.note}" for s in (a, b) if s.decided is not None and s.note]
    if notes:
        out.append(f"- Note: {'; '.join(notes)}.")
    return out + [""]
