"""The fork server (topology.kernel.forkserver) with real namespaces: its children run in the
namespace asked for, with their own session and log, and their exit statuses come back."""

import os
import signal
import subprocess
import sys
import time

import pytest

from topology.kernel import netns
from topology.kernel.forkserver import ForkServer, ForkServerError
from topology.network import Network
from topology.spec import NetworkSpec

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_children_run_in_their_namespace_and_report_exit(tmp_path, tb_name):
    env = dict(os.environ, PYTHONPATH=REPO)
    spec = NetworkSpec(name=tb_name, positions=((0, 0), (5, 0)), comm_range=10, routing="none")
    forks = ForkServer(["tests.integration.forkprobe"], env=env)
    try:
        with Network(spec) as net:
            log = str(tmp_path / "r1.log")
            probe = "tests.integration.forkprobe"
            p1 = forks.spawn(net.robot_ns(1), probe, [str(tmp_path / "r1.out"), "7"], log)
            out2, log2 = str(tmp_path / "r2.out"), str(tmp_path / "r2.log")
            p2 = forks.spawn(net.robot_ns(2), probe, [out2, "sleep"], log2, title="r2 probe")
            net.adopt(2, p2, "probe")
            assert p1.wait(timeout=20) == 7
            ino, own_session = (tmp_path / "r1.out").read_text().split("\n")[0].split()
            want = os.stat(netns.path(net.robot_ns(1))).st_ino
            assert int(ino) == want and own_session == "True"
            assert "probe ran" in open(log).read()
            assert p2.poll() is None
            # The server answers with the pid as soon as it has forked; the child names
            # itself before it runs the program, so once the probe has run the name is set.
            for _ in range(2000):
                if os.path.exists(log2) and "probe ran" in open(log2).read():
                    break
                time.sleep(0.01)
            assert open(f"/proc/{p2.pid}/comm").read().strip() == "r2 probe"
            p2.send_signal(signal.SIGKILL)
            for _ in range(200):  # poll() alone (no wait) sees the exit: a run's step loop does
                if p2.poll() is not None:
                    break
                time.sleep(0.01)
            assert p2.returncode == -signal.SIGKILL
            with pytest.raises(ForkServerError, match="no network namespace"):
                forks.spawn(tb_name + "-nope", "tests.integration.forkprobe", ["x", "0"], log)
    finally:
        forks.close()
    assert forks.proc.returncode == 0  # hanging up ends the server


def test_server_dies_with_its_parent(tmp_path):
    code = (
        "import os, sys, time; from topology.kernel.forkserver import ForkServer; "
        "f = ForkServer([]); print(f.proc.pid, flush=True); time.sleep(60)"
    )
    parent = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True,
                              env=dict(os.environ, PYTHONPATH=REPO), cwd=REPO)  # fmt: skip
    server = int(parent.stdout.readline())
    parent.kill()
    parent.wait()
    for _ in range(100):
        try:
            os.kill(server, 0)
        except ProcessLookupError:
            break
        subprocess.run(["sleep", "0.05"])
    else:
        pytest.fail("the fork server outlived its parent")


def test_hanging_up_before_the_server_is_ready_is_quiet():
    # ForkServer() does not wait for the imports; a caller that gives up at once (a network
    # whose bring-up failed) hangs up while the server still imports: it must exit 0 without
    # a traceback when its "ready" finds nobody listening.
    code = (
        "from topology.kernel.forkserver import ForkServer; "
        "f = ForkServer(['numpy', 'json']); f.close(); print(f.ready, f.proc.returncode)"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       env=dict(os.environ, PYTHONPATH=REPO), cwd=REPO, timeout=60)  # fmt: skip
    assert r.returncode == 0 and r.stdout.split() == ["False", "0"], r.stdout + r.stderr
    assert r.stderr == ""


def test_children_of_a_server_without_a_namespace_stay_in_its_own(tmp_path):
    # The sweep forks whole runs this way: no namespace, SIGINT as a fresh interpreter has it
    # (KeyboardInterrupt, so a run tears down), and a parent-death signal.
    forks = ForkServer(["tests.integration.forkprobe"], env=dict(os.environ, PYTHONPATH=REPO))
    try:
        out, log = str(tmp_path / "p.out"), str(tmp_path / "p.log")
        p = forks.spawn(None, "tests.integration.forkprobe", [out, "5"], log, pdeathsig=2)
        assert p.wait(timeout=20) == 5
        lines = open(out).read().splitlines()
        assert int(lines[0].split()[0]) == os.stat("/proc/self/ns/net").st_ino
        assert lines[2] == "True 2", "SIGINT raises KeyboardInterrupt; SIGINT when orphaned"
    finally:
        forks.close()
