"""What a testbed records about itself, so that another process can use or clean it.

One JSON file per testbed in STATE_DIR (/run/testbed, a tmpfs that a reboot empties, like the
namespaces themselves), written atomically and before any kernel object exists. It holds the
spec, the current positions, who owns the testbed and every process started in it, each as a
(pid, start time) pair so that a recycled pid is never mistaken for ours (docs/architecture.md:
names are a contract with clean-up; processes are stopped by the pids recorded, never by
name).

Ownership: a testbed built inside a `with Network(...)` block is owned by that process; when
the owner dies without tearing down, the testbed is abandoned and `testbed clean` removes it.
`testbed net up` hands the testbed over to nobody (persistent) once it is fully built, and only
`testbed net down` (or `testbed clean --all`) removes it.
"""

import contextlib
import fcntl
import json
import os
from dataclasses import asdict, dataclass, field
from typing import Any

from topology.jsonfile import write_json_atomic
from topology.spec import Impairment, NetworkSpec

DEFAULT_STATE_DIR = "/run/testbed"


def state_dir() -> str:
    return os.environ.get("TESTBED_STATE_DIR", DEFAULT_STATE_DIR)


def state_path(name: str) -> str:
    return os.path.join(state_dir(), f"{name}.json")


def run_dir(name: str) -> str:
    """A per-testbed directory for pid files, daemon state and statistics."""
    return os.path.join(state_dir(), name)


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
    os.makedirs(state_dir(), exist_ok=True)
    write_json_atomic(state_path(name), asdict(st))


def create(name: str, st: TestbedState) -> None:
    """Claim `name`: raise FileExistsError if another testbed holds it."""
    os.makedirs(state_dir(), exist_ok=True)
    fd = os.open(state_path(name), os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
    with os.fdopen(fd, "w") as f:
        f.write(st.to_json())


def read(name: str) -> TestbedState | None:
    try:
        with open(state_path(name)) as f:
            return TestbedState.from_json(f.read())
    except FileNotFoundError:
        return None
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
    return sorted(e[: -len(".json")] for e in entries if e.endswith(".json"))


@contextlib.contextmanager
def locked(name: str):
    """Serialise changes to one testbed between processes (`net move` racing `net down`)."""
    os.makedirs(state_dir(), exist_ok=True)
    with open(os.path.join(state_dir(), f".{name}.lock"), "w") as lockf:
        fcntl.flock(lockf, fcntl.LOCK_EX)
        yield
