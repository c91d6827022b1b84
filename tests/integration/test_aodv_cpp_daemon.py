"""The compiled AODV daemon (build/tb-aodv) in real namespaces, and the same under its
sanitizer builds: build/asan/tb-aodv (AddressSanitizer and UndefinedBehaviorSanitizer, every
finding fatal) and build/tsan/tb-aodv (ThreadSanitizer: the daemon has a kernel thread, a
statistics writer and a log writer beside its loop).

Each build runs one scenario on a five-robot chain (topology.Network with routing="aodv"
and aodv_daemon="cpp"; TESTBED_TB_AODV names the build): a ping across four hops is
delivered over routes of protocol 101, the statistics file reads through aodv.statsfile
with the discovery, the messages and the timers' lateness in it; a flood of hostile
datagrams (tests/integration/test_aodv_daemon.py's HOSTILE: extreme fields, forged
originators, truncated and unknown messages) is counted and survived, and the chain still
delivers; a start on an interface that does not exist is one line and status 2; SIGTERM
ends every daemon with status 0, its last statistics written, and leaves no aodv0, no
nftables table and no route of protocol 101 behind. The sanitizers write their reports to
files (log_path): there must be none. Testbeds are named "tcd" + random hex and removed
in a finally; the test files of test_aodv_daemon.py run every other daemon test against
this binary too (its aodv_daemon fixture).
"""

from __future__ import annotations

import contextlib
import dataclasses
import glob
import json
import os
import subprocess
import time
import uuid
from pathlib import Path

import pytest

from aodv.stats import read_fresh
from aodv.statsfile import DaemonStats
from common.paths import PROJECT_ROOT
from tests.integration.test_aodv_daemon import HOSTILE
from topology.kernel import netns
from topology.network import Network, destroy
from topology.spec import NetworkSpec

REPO = PROJECT_ROOT
PY = os.path.join(REPO, ".venv", "bin", "python")
BUILD = Path(REPO) / "build"
CHAIN5 = tuple((8.0 * i, 0.0) for i in range(5))
BUILDS = {
    # build: (binary, datagrams of the flood, make target)
    "plain": (BUILD / "tb-aodv", 100_000, "build/tb-aodv"),
    "asan": (BUILD / "asan" / "tb-aodv", 20_000, "build/asan/tb-aodv"),
    "tsan": (BUILD / "tsan" / "tb-aodv", 10_000, "build/tsan/tb-aodv"),
}

pytestmark = pytest.mark.skipif(os.geteuid() != 0, reason="needs root (network namespaces)")


def _binary(build: str) -> Path:
    """The build's binary: made if missing (make's own rule); skipped only where make setup
    said, in its one line, that the daemon cannot be built here."""
    path, _, target = BUILDS[build]
    unbuilt = BUILD / "tb-aodv.unbuilt"
    if unbuilt.is_file() and not (BUILD / "tb-aodv").is_file():
        pytest.skip(unbuilt.read_text().strip())
    if build != "plain" or not path.is_file():
        subprocess.run(["make", "-s", target], cwd=REPO, check=True, capture_output=True)
    assert path.is_file(), f"{target} was not built"
    return path


@contextlib.contextmanager
def cpp_net(binary: Path, positions, monkeypatch, reports: Path):
    """A network of robots at `positions` whose AODV daemons are `binary`."""
    monkeypatch.setenv("TESTBED_TB_AODV", str(binary))
    monkeypatch.setenv("ASAN_OPTIONS", f"log_path={reports}/asan:detect_leaks=1")
    monkeypatch.setenv("UBSAN_OPTIONS", f"log_path={reports}/ubsan:print_stacktrace=1")
    monkeypatch.setenv("TSAN_OPTIONS", f"log_path={reports}/tsan:exitcode=66")
    name = "tcd" + uuid.uuid4().hex[:6]
    spec = NetworkSpec(name=name, positions=tuple(positions), comm_range=10.0, routing="aodv",
                       aodv_daemon="cpp")  # fmt: skip
    try:
        with Network(spec) as net:
            wait_ready(net, len(positions))
            for k in range(1, len(positions) + 1):  # the build asked for, not another
                proc = net.process(k, "aodv")
                assert proc is not None and os.readlink(f"/proc/{proc.pid}/exe") == str(binary)
            yield net
    finally:
        destroy(name)
    assert not any(ns.startswith(f"tb-{name}-") for ns in netns.list_names())


def wait_ready(net, n, timeout=30.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if all(os.path.exists(stats_path(net, k)) for k in range(1, n + 1)):
            return
        for k in range(1, n + 1):
            proc = net.process(k, "aodv")
            assert proc is not None and proc.poll() is None, log_of(net, k)
        time.sleep(0.05)
    raise AssertionError("AODV daemons did not start")


def stats_path(net, k):
    return f"{net.state_dir}/r{k}.aodv.json"


def log_of(net, k) -> str:
    with open(f"{net.state_dir}/r{k}.aodv.log") as f:
        return f.read()


def stats(net, k):
    proc = net.process(k, "aodv")
    assert proc is not None and proc.poll() is None, log_of(net, k)
    return read_fresh(stats_path(net, k), proc).to_json()


def routes(net, k):
    out = net.exec(k, ["ip", "-4", "route", "show", "proto", "101"], capture_output=True, text=True)
    return {line.split()[0]: line for line in out.stdout.splitlines() if "/" not in line.split()[0]}


def ping(net, k, dst, *args, timeout=30):
    return net.exec(
        k, ["ping", "-n", *args, dst], capture_output=True, text=True, timeout=timeout
    ).stdout


def _ping_4_hops(net):
    out = ping(net, 1, "10.0.0.5", "-c", "2", "-W", "5")
    assert " 0% packet loss" in out, out
    assert "ttl=61" in out, out  # four hops: three routers decremented the TTL
    assert "via 10.0.0.2" in routes(net, 1)["10.0.0.5"]
    assert "proto" not in routes(net, 1)["10.0.0.5"]  # shown only for other protocols
    s1 = stats(net, 1)
    assert s1["robot"] == "r1" and s1["addr"] == "10.0.0.1"
    assert s1["discoveries_ok"] == 1 and s1["messages_sent"]["RREQ"] >= 1, s1
    assert s1["routes"]["10.0.0.5"] == {"next_hop": "10.0.0.2", "hops": 4}
    assert s1["packets_buffered"] >= 1 and s1["packets_released"] >= 1
    assert set(s1["timer_lateness_ms"]) == {"hello", "expiry"}
    with open(stats_path(net, 1)) as f:  # the rewrites: one line, as DaemonStats.compact_text
        text = f.read()
    assert text == DaemonStats.from_json(json.loads(text)).compact_text()


def _flood(net, datagrams: int):
    """HOSTILE's datagrams from robot 1 at robot 2: counted, survived, routing still works."""
    before = stats(net, 2)
    sender = net.spawn(1, [PY, "-c", HOSTILE, REPO, str(datagrams)], role="test",
                       stdout=subprocess.PIPE, text=True, cwd=REPO)  # fmt: skip
    out, _ = sender.communicate(timeout=300)
    assert out.strip() == str(datagrams)
    deadline = time.monotonic() + 60
    seen = -1
    while time.monotonic() < deadline:  # until robot 2 has read all it will read
        s2 = stats(net, 2)
        total = sum(s2["messages_received"].values()) + sum(s2["dropped"].values())
        if total == seen:
            break
        seen = total
        time.sleep(0.5)
    got = seen - sum(before["messages_received"].values()) - sum(before["dropped"].values())
    assert got >= datagrams * 9 // 10, (got, datagrams)  # the kernel may drop a few
    assert s2["dropped"].get("malformed", 0) >= datagrams // 5, s2["dropped"]
    assert s2["dropped"].get("error", 0) == 0 and s2["dropped"].get("encode_failed", 0) == 0
    assert s2["protocol_dropped"].get("hop_count", 0) > 0, s2["protocol_dropped"]
    assert len(s2["routes"]) <= 1024  # Params.route_table_limit
    for k in range(1, 6):
        proc = net.process(k, "aodv")
        assert proc is not None and proc.poll() is None, log_of(net, k)
    # Routing recovers. Not at once: the flood came from robot 1's own address, so its forged
    # RREQs may sit in robot 2's duplicate cache under the IDs robot 1 uses next (for
    # PATH_DISCOVERY_TIME), and the route to r5 may have expired while the flood ran (on a
    # loaded machine it ran longer); the RFC has robot 1 retry, and within 30 s it gets through.
    deadline = time.monotonic() + 30
    out = ping(net, 1, "10.0.0.5", "-c", "1", "-W", "5")
    while " 0% packet loss" not in out and time.monotonic() < deadline:
        out = ping(net, 1, "10.0.0.5", "-c", "1", "-W", "5")
    assert " 0% packet loss" in out, out


def _refuses_a_missing_interface(net, binary: Path):
    proc = net.exec(1, [str(binary), "--robot", "r1", "--iface", "nosuch0"],
                    capture_output=True, text=True, timeout=30)  # fmt: skip
    assert proc.returncode == 2, proc
    # As the Python daemon: what start-up made is undone ("AODV down"), then one error line.
    *logged, last = proc.stderr.splitlines()
    assert last == "tb-aodv: error: no interface nosuch0", proc.stderr
    assert all(line.startswith("r1 ") for line in logged), proc.stderr


def _sigterm_leaves_nothing(net):
    procs = {k: net.process(k, "aodv") for k in range(1, 6)}
    for proc in procs.values():
        proc.terminate()
    for k, proc in procs.items():
        assert proc.wait(timeout=30) == 0, log_of(net, k)
        final = DaemonStats.read(stats_path(net, k)).to_json()
        assert final["robot"] == f"r{k}" and final["pid"] == proc.pid
        with open(stats_path(net, k)) as f:  # every key of the Python daemon's file, no other
            text = f.read()
        doc = json.loads(text)
        assert set(doc) == {f.name for f in dataclasses.fields(DaemonStats)}
        # Byte for byte as the Python daemon writes its last file (json.dumps, indent 1).
        assert text == json.dumps(doc, indent=1, sort_keys=True) + "\n"
        assert routes(net, k) == {}
        all_routes = net.exec(k, ["ip", "-4", "route"], capture_output=True, text=True).stdout
        assert "aodv0" not in all_routes, all_routes
        links = net.exec(k, ["ip", "-o", "link"], capture_output=True, text=True).stdout
        assert "aodv0" not in links
        nft = net.exec(k, ["nft", "list", "tables"], capture_output=True, text=True).stdout
        assert "aodv" not in nft
        log = log_of(net, k)
        assert "AODV up on wlan0" in log and "AODV down" in log, log
        assert all(line.startswith(f"r{k} ") for line in log.splitlines() if line.strip()), log
    finals = [DaemonStats.read(stats_path(net, k)) for k in range(1, 6)]
    assert finals[0].discoveries_ok >= 1
    fired = {"hello": 0, "expiry": 0}
    for final in finals:
        assert final.timer_lateness_ms is not None
        for kind, timer in final.timer_lateness_ms.items():
            assert set(timer["hist"]) == {"<=10", "<=25", "<=50", "<=100", "<=200", ">200"}
            assert sum(timer["hist"].values()) == timer["n"]
            fired[kind] += timer["n"]
    assert fired["hello"] >= 1 and fired["expiry"] >= 1, fired


@pytest.mark.parametrize("build", list(BUILDS))
def test_cpp_daemon_chain_flood_and_teardown(build, monkeypatch, tmp_path):
    binary = _binary(build)
    reports = tmp_path / "reports"
    reports.mkdir()
    with cpp_net(binary, CHAIN5, monkeypatch, reports) as net:
        _ping_4_hops(net)
        _flood(net, BUILDS[build][1])
        _refuses_a_missing_interface(net, binary)
        _sigterm_leaves_nothing(net)
    found = sorted(glob.glob(f"{reports}/*"))
    assert not found, "\n".join(Path(f).read_text()[:3000] for f in found)


@pytest.mark.parametrize("build", ["asan", "tsan"])
def test_sanitized_daemons_carry_an_exploring_team(build, small_map, tmp_path):
    """Three robots explore for 150 steps with the sanitized daemon in every namespace (the
    display's too): their routes, floods and link changes run through it, and no sanitizer
    speaks. The run itself is not judged for timing: a sanitized daemon is slow."""
    binary = _binary(build)
    reports = tmp_path / "reports"
    reports.mkdir()
    env = dict(os.environ, TESTBED_TB_AODV=str(binary),
               ASAN_OPTIONS=f"log_path={reports}/asan:detect_leaks=1",
               UBSAN_OPTIONS=f"log_path={reports}/ubsan:print_stacktrace=1",
               TSAN_OPTIONS=f"log_path={reports}/tsan:exitcode=66")  # fmt: skip
    name = "tcd" + uuid.uuid4().hex[:6]
    out = tmp_path / "run"
    try:
        run = subprocess.run(
            [PY, "-m", "testbed", "run", "--robots", "3", "--comm-range", "4",
             "--laser-range", "1.5", "--map", small_map, "--max-steps", "150", "--time-scale",
             "2", "--aodv-daemon", "cpp", "--name", name, "--quiet", "--out", str(out)],
            capture_output=True, text=True, timeout=600, cwd=REPO, env=env,
        )  # fmt: skip
    finally:
        destroy(name)
    with open(out / "result.json") as f:
        result = json.load(f)
    assert result["status"] in ("complete", "step_cap"), run.stderr
    assert result["aodv_daemon"] == "cpp"
    sent = 0
    for k in (1, 2, 3, 4):  # r4: the display's
        s = DaemonStats.read(str(out / "aodv" / f"r{k}.json")).to_json()
        sent += sum(s["messages_sent"].values())
    assert sent > 0
    found = sorted(glob.glob(f"{reports}/*"))
    assert not found, "\n".join(Path(f).read_text()[:3000] for f in found)
    assert not any(ns.startswith(f"tb-{name}-") for ns in netns.list_names())


def _sleeps(pid: int) -> int:
    """How often the daemon's loop (its main thread) has gone to sleep so far."""
    with open(f"/proc/{pid}/task/{pid}/status") as f:
        return int(next(ln for ln in f if ln.startswith("voluntary_ctxt_switches")).split()[1])


def test_idle_daemon_without_routes_sleeps_through_the_route_use_poll(tmp_path):
    """With no valid route the route-use poll has nothing to ask: the loop does not wake for
    it (ACTIVE_ROUTE_TIMEOUT / 3, 1 s), only for the core's deadlines, here a HELLO check
    every 10 s; so over 5 idle seconds it sleeps about once, not five times."""
    binary = _binary("plain")
    name = "tcd" + uuid.uuid4().hex[:6]
    spec = NetworkSpec(name=name, positions=CHAIN5[:1], comm_range=10.0, routing="none")
    stats_file = tmp_path / "r1.json"
    try:
        with Network(spec) as net:
            argv = [str(binary), "--netns", net.robot_ns(1), "--robot", "r1", "--stats",
                    str(stats_file), "--stats-period", "0",
                    "--set", "hello_interval_ms=10000"]  # fmt: skip
            proc = subprocess.Popen(argv, stderr=subprocess.PIPE, text=True)
            try:
                deadline = time.monotonic() + 30
                while not stats_file.exists():
                    assert proc.poll() is None and time.monotonic() < deadline, proc.stderr
                    time.sleep(0.02)
                time.sleep(0.5)  # past the start-up's hand-offs
                before = _sleeps(proc.pid)
                time.sleep(5.0)
                assert _sleeps(proc.pid) - before <= 2
            finally:
                proc.terminate()
                assert proc.wait(timeout=10) == 0
    finally:
        destroy(name)
