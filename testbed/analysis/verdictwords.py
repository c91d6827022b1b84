"""The words a verdict on a claim is said in (testbed.analysis.verdicts decides them; the
sections that judge claims of their own, such as testbed.analysis.middlewares, say theirs in
the same words). A module of its own so that those sections need nothing of verdicts.py,
which reads their tables."""

HOLDS, PARTLY, FAILS, NO_DATA = "holds", "partly holds", "does not hold", "not enough data"
TOO_FEW = "too few runs to decide"
