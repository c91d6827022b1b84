"""What a testbed records about itself, so that another process can use or clean it.

One JSON file per testbed in STATE_DIR (/run/testbed, a tmpfs that a reboot empties, like the
namespaces themselves), written atomically and before any kernel object exists. It holds the
spec, the current positions, who owns the testbed and every process started in it, each as a
(pid, start time) pair so that a recycled pid is never mistaken for ours (docs/architecture.md:
names are a contract with clean-up; processes are stopped by the pids recorded, never by
name).

Who may write: only the user who runs the testbeds (root). Whatever the caller's umask, the
state dir is 0755, each state file 0644, each lock file 0600 and each run dir 0700 (it holds
the control sockets: the feed, the body link, the ns-3 medium; others cannot even reach
them). A state file someone else could have written (not ours, or writable by group or
others, or a symlink) is not trusted: `read` raises UntrustedState, and teardown then
signals none of the processes it names (topology.teardown.destroy).

Ownership: a testbed built inside a `with Network(...)` block is owned by that process; when
the owner dies without tearing down, the testbed is abandoned and `testbed clean` removes it.
`testbed net up` hands the testbed over to nobody (persistent) once it is fully built, and only
`testbed net down` (or `testbed clean --all`) removes it.
"""

import contextlib
import fcntl
import json
import os
import stat
from dataclasses import asdict, dataclass, field
from typing import Any

from common.errors import UsageError
from common.jsonfile import write_json_atomic
from topology.names import NAME_PATTERN
from topology.spec import Impairment, NetworkSpec

DEFAULT_STATE_DIR = "/run/testbed"
STATE_DIR_MODE = 0o755
RUN_DIR_MODE = 0o700
STATE_FILE_MODE = 0o644
LOCK_FILE_MODE = 0o600


class UntrustedState(UsageError):
    """A state file that someone other than this user could have written."""


def state_dir() -> str:
    return os.environ.get("TESTBED_STATE_DIR", DEFAULT_STATE_DIR)


def state_path(name: str) -> str:
    return os.path.join(state_dir(), f"{name}.json")


def run_dir(name: str) -> str:
    """A per-testbed directory for pid files, daemon state and statistics."""
    return os.path.join(state_dir(), name)


def _own_dir(path: str, mode: int) -> None:
    """`path` is a directory of this user's with exactly `mode`, whatever the umask (an
    existing one with a laxer mode is set right); UsageError for a symlink, a file or a
    directory of someone else's there."""
    os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
    try:
        os.mkdir(path, mode)
    except FileExistsError:
        pass
    st = os.lstat(path)
    if not stat.S_ISDIR(st.st_mode) or st.st_uid != os.geteuid():
        raise UsageError(
            f"{path} is not a directory of uid {os.geteuid()} (owner uid {st.st_uid}, "
            f"mode {stat.filemode(st.st_mode)}): not using it; remove it by hand"
        )
    if stat.S_IMODE(st.st_mode) != mode:
        os.chmod(path, mode)


def make_state_dir() -> None:
    _own_dir(state_dir(), STATE_DIR_MODE)


def make_run_dir(name: str) -> str:
    """The testbed's run dir, made (or set right) 0700: for root alone."""
    make_state_dir()
    _own_dir(run_dir(name), RUN_DIR_MODE)
    return run_dir(name)


def _check_trusted(path: str, st: os.stat_result) -> None:
    """UntrustedState unless `st` (of `path`) is a regular file of this user's (or root's)
    that nobody else may write."""
    if (
        not stat.S_ISREG(st.st_mode)
        or st.st_uid not in (0, os.geteuid())
        or st.st_mode & (stat.S_IWGRP | stat.S_IWOTH)
    ):
        raise UntrustedState(
            f"{path} (owner uid {st.st_uid}, mode {stat.filemode(st.st_mode)}) may have been "
            "written by another user: its records are not trusted"
        )


def proc_start_time(pid: int) -> int | None:
    """The kernel's start time of `pid` (clock ticks since boot), None if no such process."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            stat = f.read()
    except (FileNotFoundError, ProcessLookupError):
        return None
    # Field 2 (comm) may hold spaces and parentheses: split after its closing parenthesis.
    fields = stat[stat.rfind(")") + 2 :].split()
    return int(fields[19])


def is_alive(pid: int, start: int | None) -> bool:
    """True if `pid` is still the very process that was recorded (not a zombie)."""
    now = proc_start_time(pid)
    if now is None or now != start:
        return False
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("State:"):
                    return "Z" not in line.split()[1]
    except FileNotFoundError:
        return False
    return True


@dataclass
class ProcessRecord:
    pid: int
    start: int | None
    robot: int
    role: str


@dataclass
class TestbedState:
    __test__ = False

    spec: dict[str, Any]
    positions: list[list[float]]
    owner_pid: int | None
    owner_start: int | None
    persistent: bool = False
    processes: list[ProcessRecord] = field(default_factory=list)
    # Per-link impairments set by hand: "i-j" -> Impairment fields, on top of the spec's.
    link_impairments: dict[str, dict[str, float]] = field(default_factory=dict)
    # What the medium has applied to each link end (ifname -> Impairment fields), so that a
    # process attaching later knows what to undo.
    applied: dict[str, dict[str, float]] = field(default_factory=dict)

    @classmethod
    def new(cls, spec: NetworkSpec) -> "TestbedState":
        pid = os.getpid()
        return cls(
            spec=spec_to_dict(spec),
            positions=[list(p) for p in spec.positions],
            owner_pid=pid,
            owner_start=proc_start_time(pid),
        )

    def abandoned(self) -> bool:
        """Nobody will tear this testbed down: not persistent, and its owner is gone."""
        if self.persistent:
            return False
        return self.owner_pid is None or not is_alive(self.owner_pid, self.owner_start)

    def to_json(self) -> str:
        return json.dumps(asdict(self), indent=1) + "\n"

    @classmethod
    def from_json(cls, text: str) -> "TestbedState":
        raw = json.loads(text)
        raw["processes"] = [ProcessRecord(**p) for p in raw.get("processes", [])]
        return cls(**raw)


def spec_to_dict(spec: NetworkSpec) -> dict[str, Any]:
    d = asdict(spec)
    d["positions"] = [list(p) for p in spec.positions]
    return d


def spec_from_dict(d: dict[str, Any]) -> NetworkSpec:
    d = dict(d)
    d["positions"] = tuple(tuple(p) for p in d["positions"])
    d["impairment"] = Impairment(**d["impairment"])
    return NetworkSpec(**d)


def write(name: str, st: TestbedState) -> None:
    make_state_dir()
    write_json_atomic(state_path(name), asdict(st), mode=STATE_FILE_MODE)


def create(name: str, st: TestbedState) -> None:
    """Claim `name`: raise FileExistsError if another testbed holds it."""
    make_state_dir()
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW
    fd = os.open(state_path(name), flags, STATE_FILE_MODE)
    os.fchmod(fd, STATE_FILE_MODE)  # the umask does not decide who may write it
    with os.fdopen(fd, "w") as f:
        f.write(st.to_json())


def exists(name: str) -> bool:
    """Whether a state file (trusted or not) is there for `name`."""
    return os.path.lexists(state_path(name))


def read(name: str) -> TestbedState | None:
    """The state of testbed `name`; None if it has none (or a torn or foreign one);
    UntrustedState if its file may have been written by another user."""
    path = state_path(name)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    except FileNotFoundError:
        return None
    except OSError as exc:  # ELOOP: a symlink
        raise UntrustedState(
            f"{path} is not a regular file ({exc.strerror}): its records are not trusted"
        ) from None
    with os.fdopen(fd) as f:
        _check_trusted(path, os.fstat(fd))
        try:
            return TestbedState.from_json(f.read())
        except (ValueError, TypeError, KeyError):
            return None  # a torn or foreign file: treated as no state (clean may remove it)


def remove(name: str) -> None:
    """Forget testbed `name`: its state file and its lock file (the testbed is gone)."""
    for p in (state_path(name), os.path.join(state_dir(), f".{name}.lock")):
        with contextlib.suppress(FileNotFoundError):
            os.unlink(p)


def names() -> list[str]:
    try:
        entries = os.listdir(state_dir())
    except FileNotFoundError:
        return []
    found = (e[: -len(".json")] for e in entries if e.endswith(".json"))
    return sorted(n for n in found if NAME_PATTERN.fullmatch(n))  # nothing else is ours


@contextlib.contextmanager
def locked(name: str):
    """Serialise changes to one testbed between processes (`net move` racing `net down`)."""
    make_state_dir()
    path = os.path.join(state_dir(), f".{name}.lock")
    fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, LOCK_FILE_MODE)
    try:
        if os.fstat(fd).st_uid == os.geteuid():
            os.fchmod(fd, LOCK_FILE_MODE)  # nobody else may open it (and hold the lock)
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)
