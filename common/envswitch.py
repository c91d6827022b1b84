"""The environment switches of the testbed: each named once, with the values it knows.

`TESTBED_REALTIME` (real-time priority: 1, the default, or 0 for off) and `TESTBED_STEPCORE`
(the per-step work: compiled, the default where build/libstepcore.so loads, or numpy) are
read by processes far from the command line (robots, the world, the ns-3 medium), so a
misspelt value used to be taken as the default without a word (`TESTBED_STEPCORE=nmupy` ran
the compiled core; `TESTBED_REALTIME=false` left real-time priority on). `value(name)` is the
one reading of a switch; `check()`, which `testbed` calls before any command, refuses an
unknown value in one line (UsageError, exit 2).
"""

from __future__ import annotations

import os

from common.errors import UsageError

# name: (the values it knows, the first being what unset means)
SWITCHES: dict[str, tuple[str, ...]] = {
    "TESTBED_REALTIME": ("1", "0"),
    "TESTBED_STEPCORE": ("compiled", "numpy"),
}


def value(name: str) -> str:
    """The switch's value (its default when unset or empty), lower case; UsageError for a
    value it does not know."""
    known = SWITCHES[name]
    got = os.environ.get(name, "").strip().lower() or known[0]
    if got not in known:
        shown = os.environ.get(name, "")[:40].encode("unicode_escape").decode()
        raise UsageError(f"{name}={shown!r} is not one of {', '.join(known)}")
    return got


def check() -> None:
    """Every switch's value is one it knows (else UsageError, one line)."""
    for name in SWITCHES:
        value(name)
