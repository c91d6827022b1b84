"""A testbed's teardown: everything testbed NAME made, removed from its names and state file
alone (topology.network.Network.down, `testbed net down`, `testbed clean`).

Theory of operation. `destroy` is the same function for a clean exit, an exception during
bring-up, `testbed net down` and `testbed clean`: stop the recorded processes (SIGTERM, then
SIGKILL; the captures last, so that what the daemons send as they stop is in the pcaps), then
any other process still inside the testbed's namespaces, then remove the namespaces (which
takes every interface with them), keep the daemons' logs next to the captures, and remove the
run directory and the state. It needs nothing from the process that built the testbed.
"""

import logging
import os
import shutil
import subprocess
import time

from topology import names, state
from topology.kernel import netns, processes

log = logging.getLogger(__name__)

CAPTURE_DRAIN_S = 0.2  # lets tcpdump read what is still queued for it before it stops


def our_namespaces(name: str) -> list[str]:
    return [ns for ns in netns.list_names() if (names.parse_ns(ns) or ("",))[0] == name]


def destroy(name: str, children: dict[int, subprocess.Popen] | None = None) -> None:
    """Remove everything testbed `name` made: processes, namespaces, run dir, state. A state
    file another user could have written is ignored (one warning): none of the processes it
    names is signalled, only those the kernel shows inside the testbed's namespaces."""
    try:
        st = state.read(name)
    except state.UntrustedState as exc:
        log.warning("%s; signalling only the processes inside tb-%s-* namespaces", exc, name)
        st = None
    namespaces = our_namespaces(name)
    if st is not None:
        # Captures last: what the daemons send as they stop belongs in the pcaps.
        last = [p for p in st.processes if p.role == "tcpdump"]
        processes.stop([p for p in st.processes if p.role != "tcpdump"], children)
        if last:
            time.sleep(CAPTURE_DRAIN_S)
            processes.stop(last, children)
    stray = [pid for pid in processes.pids_in_namespaces(namespaces) if pid != os.getpid()]
    if stray:
        processes.stop(
            [state.ProcessRecord(pid, state.proc_start_time(pid), 0, "stray") for pid in stray],
            children,
        )
    for ns in namespaces:
        netns.remove(ns)
    _keep_logs(name, st)
    shutil.rmtree(state.run_dir(name), ignore_errors=True)
    state.remove(name)


def _keep_logs(name: str, st: state.TestbedState | None) -> None:
    """Nothing is lost: when the testbed captured packets, the daemons' logs and statistics
    (written to its run dir as they stop) go next to the pcaps, in CAPTURE_DIR/daemons/."""
    capture_dir = st.spec.get("capture_dir") if st else None
    src = state.run_dir(name)
    if not capture_dir or not os.path.isdir(src):
        return
    dst = os.path.join(capture_dir, "daemons")
    os.makedirs(dst, exist_ok=True)
    for entry in os.listdir(src):
        if entry.endswith((".log", ".json")):
            shutil.copy2(os.path.join(src, entry), os.path.join(dst, entry))
