"""The state files: modes set whatever the umask, and a record that another user could have
written is never acted on (no process it names is signalled)."""

import contextlib
import os
import stat
import subprocess

import pytest

from common.errors import UsageError
from topology import state
from topology.network import destroy
from topology.spec import NetworkSpec


@pytest.fixture
def state_dir(tmp_path, monkeypatch):
    d = tmp_path / "state"
    monkeypatch.setenv("TESTBED_STATE_DIR", str(d))
    return d


@contextlib.contextmanager
def umask(mask: int):
    old = os.umask(mask)
    try:
        yield
    finally:
        os.umask(old)


def mode(path) -> int:
    return stat.S_IMODE(os.lstat(path).st_mode)


def a_state(name: str) -> state.TestbedState:
    return state.TestbedState.new(NetworkSpec(name=name, positions=((0, 0),), comm_range=5.0))


def test_modes_are_root_only_write_whatever_the_umask(state_dir):
    with umask(0):
        st = a_state("um1")
        state.create("um1", st)
        assert mode(state_dir) == 0o755 and mode(state_dir / "um1.json") == 0o644
        state.write("um1", st)  # rewritten through a temporary file: the same mode
        assert mode(state_dir / "um1.json") == 0o644
        with state.locked("um1"):
            assert mode(state_dir / ".um1.lock") == 0o600
        os.chmod(state_dir, 0o777)  # a state dir made lax earlier is set right
        state.write("um1", st)
        assert mode(state_dir) == 0o755


def test_a_run_dir_is_for_its_owner_alone(state_dir):
    with umask(0):
        path = state.make_run_dir("um2")
    assert mode(path) == 0o700
    os.rmdir(path)
    os.symlink("/tmp", path)  # not a directory of ours: refused, not followed
    with pytest.raises(UsageError, match="not a directory"):
        state.make_run_dir("um2")


def sleeper() -> subprocess.Popen:
    return subprocess.Popen(["sleep", "60"], start_new_session=True)


def record(proc) -> state.ProcessRecord:
    return state.ProcessRecord(proc.pid, state.proc_start_time(proc.pid), 0, "view")


@pytest.mark.parametrize("tamper", ["mode 0666", "owner nobody", "symlink"])
def test_teardown_signals_no_process_named_by_a_state_file_another_user_could_write(
    state_dir, tamper, caplog
):
    if tamper == "owner nobody" and os.geteuid() != 0:
        pytest.skip("only root can give a file to another user")
    victim = sleeper()
    try:
        st = a_state("um3")
        st.processes.append(record(victim))
        state.create("um3", st)
        path = state_dir / "um3.json"
        if tamper == "mode 0666":
            os.chmod(path, 0o666)
        elif tamper == "owner nobody":
            os.chown(path, 65534, 65534)
        else:
            os.rename(path, state_dir / "elsewhere.json")
            os.symlink(state_dir / "elsewhere.json", path)
        with pytest.raises(state.UntrustedState):
            state.read("um3")
        destroy("um3")
        assert victim.poll() is None, "a process named by an untrusted record was signalled"
        assert not os.path.lexists(path)  # the untrusted record itself is gone
        warnings = [r for r in caplog.records if r.levelname == "WARNING"]
        assert len(warnings) == 1 and "not trusted" in warnings[0].getMessage()
        # The same record, written by this user alone: its process is stopped.
        state.create("um3", st)
        destroy("um3")
        assert victim.wait(timeout=5) is not None
    finally:
        victim.kill()
        victim.wait()


def test_only_testbed_names_are_listed(state_dir):
    state.create("um4", a_state("um4"))
    (state_dir / "Evil Name.json").write_text("{}")
    (state_dir / "x\n.json").write_text("{}")
    assert state.names() == ["um4"]
