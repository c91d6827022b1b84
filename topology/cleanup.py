"""`testbed clean`: remove what dead or abandoned testbeds left behind, and only that.

A testbed is found by its names (topology.names) and its state file (topology.state):
- a state file whose owner process is gone and which was never handed over as persistent
  (a run or test that crashed or was SIGKILLed, or a `net up` killed half-way);
- namespaces matching our pattern that have no state file at all (a state dir wiped by hand);
- a state file of a persistent testbed whose namespaces are gone (stale record).
Persistent testbeds that are up, and testbeds whose owner still runs, are left alone unless
`everything` is set (`testbed clean --all`).
"""

import fcntl
import logging
import os

from topology import names, state
from topology.kernel import netns
from topology.network import destroy

log = logging.getLogger(__name__)


def leftovers(everything: bool = False) -> list[str]:
    """Names of the testbeds that clean would remove."""
    found = set()
    recorded = set(state.names())
    for name in recorded:
        try:
            st = state.read(name)
        except state.UntrustedState:
            st = None  # removed; destroy says why and signals none of its records
        stale = st is not None and st.persistent and not netns.exists(names.medium_ns(name))
        if everything or st is None or st.abandoned() or stale:
            found.add(name)
    for ns in netns.list_names():
        parsed = names.parse_ns(ns)
        if parsed and (everything or parsed[0] not in recorded):
            found.add(parsed[0])
    return sorted(found)


def _orphan_locks() -> None:
    """Lock files of testbeds with no state left (older versions did not remove them): each
    is removed only if nobody holds it."""
    try:
        entries = os.listdir(state.state_dir())
    except FileNotFoundError:
        return
    recorded = set(state.names())
    for entry in entries:
        if not (entry.startswith(".") and entry.endswith(".lock")):
            continue
        if entry[1:-5] in recorded:
            continue
        path = os.path.join(state.state_dir(), entry)
        try:
            with open(path) as f:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
                os.unlink(path)
        except OSError:
            continue  # held by a live testbed, or already gone


def clean(everything: bool = False) -> list[str]:
    _orphan_locks()
    removed = []
    for name in leftovers(everything):
        with state.locked(name):
            # Re-check under the lock: the owner may have finished a bring-up meanwhile.
            if name in leftovers(everything):
                destroy(name)
                removed.append(name)
                log.info("removed testbed %s", name)
    return removed
