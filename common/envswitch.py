"""The environment switches of the testbed: each named once, with the values it knows.

`TESTBED_REALTIME` (real-time priority: 1, the default, or 0 for off) and `TESTBED_STEPCORE`
(the per-step work: compiled, the default where build/libstepcore.so loads, or numpy) are
read by processes far from the command line (robots, the world, the ns-3 medium), so a
misspelt value used to be taken as the default without a word (`TESTBED_STEPCORE=nmupy` ran
the compiled core; `TESTBED_REALTIME=false` left real-time priority on). `value(name)` is the
one reading of a switch; `check()`, which `testbed` calls before any command, refuses an
unknown value in one line (UsageError, exit 2). `TESTBED_STEPCORE_LIBRARY` names another
build of the step core to load (the sanitized one its test runs): `library(name)` takes only
a file inside the project's build/ directory, as every process of a run, root's included,
loads it.
"""

from __future__ import annotations

import os
from pathlib import Path

from common.errors import UsageError
from common.paths import PROJECT_ROOT

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


# name: the directory of the project its file must be in
LIBRARIES: dict[str, str] = {"TESTBED_STEPCORE_LIBRARY": "build"}


def library(name: str) -> Path | None:
    """The file a library variable names (None when unset or empty), resolved; UsageError
    when it is not inside the project's directory for it."""
    got = os.environ.get(name, "")
    if not got:
        return None
    where = (Path(PROJECT_ROOT) / LIBRARIES[name]).resolve()
    path = Path(got).resolve()
    if not path.is_relative_to(where):
        shown = got[:60].encode("unicode_escape").decode()
        raise UsageError(f"{name}={shown!r} is not a file in {where}")
    return path


def check() -> None:
    """Every switch's value is one it knows and every library variable names a file in the
    project (else UsageError, one line)."""
    for name in SWITCHES:
        value(name)
    for name in LIBRARIES:
        library(name)
