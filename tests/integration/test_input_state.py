"""A testbed brought up under `umask 000` is still root's alone: its state dir, state file,
run dir and feed socket; a record another user slipped into its state file is not acted on."""

import json
import os
import shutil
import stat
import subprocess
import sys

import pytest

from topology import state
from topology.inputs import feed
from topology.kernel import netns

TESTBED = [sys.executable, "-m", "testbed.cli"]
REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def tb(*args, umask: int | None = None) -> subprocess.CompletedProcess:
    def set_umask():
        if umask is not None:
            os.umask(umask)

    return subprocess.run(TESTBED + list(args), capture_output=True, text=True, cwd=REPO,
                          preexec_fn=set_umask)  # fmt: skip


def mode(path: str) -> int:
    return stat.S_IMODE(os.lstat(path).st_mode)


def test_under_umask_000_the_state_and_the_feed_socket_are_root_only(tb_name):
    r = tb("net", "up", tb_name, "--robots", "2", "--comm-range", "10", "--feed", umask=0)
    assert r.returncode == 0, r.stderr
    try:
        assert mode(state.state_dir()) == 0o755
        assert mode(state.state_path(tb_name)) == 0o644
        assert mode(state.run_dir(tb_name)) == 0o700
        sock = feed.socket_path(tb_name)
        assert stat.S_ISSOCK(os.lstat(sock).st_mode) and mode(sock) == 0o600
        # Still so once the feed has saved positions (the file is rewritten, not edited).
        feed.send(sock, ["2 9 0"])
        assert tb("net", "links", tb_name).returncode == 0
        assert mode(state.state_path(tb_name)) == 0o644
        if shutil.which("setpriv") is None:
            pytest.skip("setpriv (util-linux) not installed")
        probe = ("import socket, sys; s = socket.socket(socket.AF_UNIX); "
                 "sys.exit(0 if s.connect_ex(sys.argv[1]) == 0 else 3)")  # fmt: skip
        other = subprocess.run(["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups",
                                sys.executable, "-c", probe, sock])  # fmt: skip
        assert other.returncode == 3, "another user could connect to the feed socket"
    finally:
        assert tb("net", "down", tb_name).returncode == 0


def test_net_down_signals_no_process_from_a_record_another_user_wrote(tb_name):
    r = tb("net", "up", tb_name, "--robots", "2", "--comm-range", "10")
    assert r.returncode == 0, r.stderr
    victim = subprocess.Popen(["sleep", "60"], start_new_session=True)  # "a user's process"
    try:
        path = state.state_path(tb_name)
        with open(path) as f:
            doc = json.load(f)
        doc["processes"].append({"pid": victim.pid, "start": state.proc_start_time(victim.pid),
                                 "robot": 0, "role": "view"})  # fmt: skip
        with open(path, "w") as f:
            json.dump(doc, f)
        os.chown(path, 65534, 65534)  # as if that user had written it
        os.chmod(path, 0o666)
        down = tb("net", "down", tb_name)
        assert down.returncode == 0, down.stderr
        assert victim.poll() is None, "net down killed a process named by another user"
        lines = down.stderr.strip().splitlines()
        assert len(lines) == 1 and "not trusted" in lines[0], down.stderr
        assert not netns.exists(f"tb-{tb_name}-m") and not os.path.lexists(path)
    finally:
        victim.kill()
        victim.wait()
