"""Starting programs inside a robot's namespace and stopping them by their recorded pids."""

import contextlib
import os
import signal
import subprocess
import time

from topology.kernel import netns
from topology.state import ProcessRecord, is_alive, proc_start_time


def spawn(ns: str, argv: list[str], **popen_kwargs) -> subprocess.Popen:
    """Start argv in namespace `ns`; the Popen's pid is the program's own (ip netns exec execs).

    The child gets its own session so that a Ctrl-C meant for the controlling terminal does
    not reach it: the testbed stops its processes itself, in order."""
    popen_kwargs.setdefault("stdin", subprocess.DEVNULL)
    popen_kwargs.setdefault("start_new_session", True)
    return subprocess.Popen(netns.popen_argv(ns, argv), **popen_kwargs)


def record(proc: subprocess.Popen, robot: int, role: str) -> ProcessRecord:
    return ProcessRecord(pid=proc.pid, start=proc_start_time(proc.pid), robot=robot, role=role)


def stop(
    records: list[ProcessRecord],
    children: dict[int, subprocess.Popen] | None = None,
    grace: float = 3.0,
) -> None:
    """SIGTERM every recorded process that is still the one recorded, wait up to `grace`
    seconds for them to exit, then SIGKILL the rest.

    `children` are the Popen objects of the processes this process started itself: they are
    reaped through their Popen, so whoever holds it still reads the true exit status."""
    children = children or {}
    # Never a pid that names a group or everyone (0, -1, ...), init, or this process.
    records = [r for r in records if type(r.pid) is int and r.pid > 1 and r.pid != os.getpid()]

    def alive(r: ProcessRecord) -> bool:
        if r.pid in children:
            return children[r.pid].poll() is None
        return is_alive(r.pid, r.start)

    live = [r for r in records if alive(r)]
    for sig in (signal.SIGTERM, signal.SIGKILL):
        for r in live:
            _signal(r.pid, sig)
        deadline = time.monotonic() + grace
        while live and time.monotonic() < deadline:
            live = [r for r in live if alive(r)]
            if live:
                time.sleep(0.01)


def _signal(pid: int, sig: int) -> None:
    with contextlib.suppress(ProcessLookupError):
        os.kill(pid, sig)


def pids_in_namespace(ns: str) -> list[int]:
    """Every process whose network namespace is `ns` (what `ip netns pids` reports)."""
    return pids_in_namespaces([ns])


def pids_in_namespaces(namespaces: list[str]) -> list[int]:
    """Every process inside one of `namespaces`, in one pass over /proc (a pass per
    namespace costs seconds at 1000 robots)."""
    wanted = set()
    for ns in namespaces:
        try:
            st = os.stat(netns.path(ns))
        except FileNotFoundError:
            continue
        wanted.add((st.st_dev, st.st_ino))
    if not wanted:
        return []
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            st = os.stat(f"/proc/{entry}/ns/net")
        except (FileNotFoundError, PermissionError, ProcessLookupError):
            continue
        if (st.st_dev, st.st_ino) in wanted:
            found.append(int(entry))
    return found
