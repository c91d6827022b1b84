"""The `testbed net ...` and `testbed clean` commands, end to end, as a user runs them."""

import os
import re
import shutil
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from topology import names, state
from topology.kernel import netns, processes

TESTBED = [sys.executable, "-m", "testbed.cli"]
REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def tb(*args, **kw) -> subprocess.CompletedProcess:
    kw.setdefault("capture_output", True)
    kw.setdefault("text", True)
    kw.setdefault("cwd", REPO)
    return subprocess.run(TESTBED + list(args), **kw)


def ping_ttl(name: str, src: int, dst: int, wait: float) -> int | None:
    """Ping until it answers or `wait` seconds pass; the reply's TTL, or None."""
    deadline = time.monotonic() + wait
    while True:
        r = tb("net", "exec", name, f"r{src}", "--", "ping", "-c1", "-W1", names.robot_addr(dst))
        m = re.search(r"ttl=(\d+)", r.stdout)
        if r.returncode == 0 and m:
            return int(m[1])
        if time.monotonic() > deadline:
            return None
        time.sleep(0.3)


@pytest.mark.slow
def test_babel_chain_four_hops_break_and_restore(tb_name):
    up = tb("net", "up", tb_name, "--robots", "5", "--layout", "chain", "--spacing", "8",
            "--comm-range", "10", "--routing", "babel")  # fmt: skip
    assert up.returncode == 0, up.stderr
    try:
        assert tb("net", "links", tb_name).stdout.split("\n")[:4] == ["1 2", "2 3", "3 4", "4 5"]
        ttl = ping_ttl(tb_name, 1, 5, wait=30)
        # The reply leaves robot 5 with TTL 64 and crosses robots 4, 3, 2: 4 hops.
        assert ttl == 64 - 3, f"reply TTL {ttl}"
        moved = tb("net", "move", tb_name, "r3", "16", "30")
        assert moved.returncode == 0 and moved.stdout.split("\n")[:2] == ["- 2 3", "- 3 4"]
        lost = tb("net", "exec", tb_name, "r1", "--", "ping", "-c3", "-W1", "10.0.0.5")
        assert lost.returncode != 0, "robot 3 left: no path from 1 to 5"
        assert tb("net", "move", tb_name, "r3", "16", "0").returncode == 0
        assert ping_ttl(tb_name, 1, 5, wait=30) == 61, "path restored when robot 3 came back"
    finally:
        down = tb("net", "down", tb_name)
        assert down.returncode == 0, down.stderr
    assert not [ns for ns in netns.list_names() if tb_name in ns]
    assert state.read(tb_name) is None


def ttl_becomes(name: str, src: int, dst: int, ttl: int, wait: float) -> bool:
    """Ping until a reply comes with `ttl` (the route has that many hops) or `wait` passes."""
    deadline = time.monotonic() + wait
    while time.monotonic() < deadline:
        if ping_ttl(name, src, dst, wait=1) == ttl:
            return True
        time.sleep(0.5)
    return False


@pytest.mark.slow
@pytest.mark.skipif(
    shutil.which("batmand") is None,
    reason="batmand (package batmand) is not installed; some distributions do not have it",
)
def test_batman_chain_converges_and_diamond_reroutes_around_a_moved_robot(tb_name):
    """--routing batman (batmand, proactive): a 5-robot chain converges to 4-hop routes, and
    in a diamond the route leaves a next hop that walks away for the other side."""
    up = tb("net", "up", tb_name, "--robots", "5", "--layout", "chain", "--spacing", "8",
            "--comm-range", "10", "--routing", "batman", "--time-scale", "5")  # fmt: skip
    assert up.returncode == 0, up.stderr
    try:
        assert ping_ttl(tb_name, 1, 5, wait=40) == 61
        # No batmand socket file escaped to the host's /run (each daemon has its own /run).
        assert not os.path.exists("/run/batmand.socket")
        # Robots 2 and 4 step aside, robot 3 joins them: 1 - {2, 3} - 4 - 5 is a diamond.
        for k, (x, y) in ((2, (6, 4)), (3, (6, -4)), (4, (12, 0)), (5, (20, 0))):
            assert tb("net", "move", tb_name, f"r{k}", str(x), str(y)).returncode == 0
        # batmand picks by link quality (TQ), which takes some OGMs to favour the new path.
        assert ttl_becomes(tb_name, 1, 5, 62, wait=60)  # 3 hops through 2 or 3
        route = tb("net", "exec", tb_name, "r1", "--", "ip", "route", "get", "10.0.0.5").stdout
        via = int(re.search(r"via 10\.0\.0\.(\d)", route)[1])
        other = 5 - via  # 2 <-> 3
        assert tb("net", "move", tb_name, f"r{via}", "6", "40").returncode == 0
        assert ttl_becomes(tb_name, 1, 5, 62, wait=60), "no route round the robot that left"
        route = tb("net", "exec", tb_name, "r1", "--", "ip", "route", "get", "10.0.0.5").stdout
        assert f"via 10.0.0.{other}" in route, route
    finally:
        down = tb("net", "down", tb_name)
        assert down.returncode == 0, down.stderr
    assert not [ns for ns in netns.list_names() if tb_name in ns]


def test_oracle_routes_follow_every_move_with_no_control_traffic(tb_name):
    """--routing oracle: the controller's routes are in the kernel when `net move` returns."""
    up = tb("net", "up", tb_name, "--robots", "5", "--layout", "chain", "--spacing", "8",
            "--comm-range", "10", "--routing", "oracle")  # fmt: skip
    assert up.returncode == 0, up.stderr
    try:
        routes = tb("net", "exec", tb_name, "r1", "--", "ip", "route", "show", "proto", "102")
        assert "10.0.0.5 via 10.0.0.2 dev wlan0 onlink" in routes.stdout, routes.stdout
        assert ping_ttl(tb_name, 1, 5, wait=2) == 61  # at once: nothing to discover
        # 3 leaves: the chain breaks, and the routes across it go at once.
        assert tb("net", "move", tb_name, "r3", "16", "30").returncode == 0
        r1 = tb("net", "exec", tb_name, "r1", "--", "ip", "route", "show", "proto", "102")
        assert "10.0.0.5" not in r1.stdout and "10.0.0.2 dev wlan0" in r1.stdout, r1.stdout
        assert (
            tb("net", "move", tb_name, "r3", "16", "6").returncode == 0
        )  # back, 10 m from 2 and 4
        r5 = tb("net", "exec", tb_name, "r5", "--", "ip", "route", "show", "proto", "102")
        assert "10.0.0.1 via 10.0.0.4 dev wlan0 onlink" in r5.stdout, r5.stdout
        assert ping_ttl(tb_name, 5, 1, wait=2) == 61
        # Nothing on the radio but the pings: the oracle sends no control packet.
        counters = tb("net", "exec", tb_name, "r2", "--", "cat", "/proc/net/snmp").stdout
        udp = [line.split() for line in counters.splitlines() if line.startswith("Udp:")]
        assert int(udp[1][udp[0].index("OutDatagrams")]) == 0
    finally:
        down = tb("net", "down", tb_name)
        assert down.returncode == 0, down.stderr
    assert not [ns for ns in netns.list_names() if tb_name in ns]


def test_los_walls_of_the_office_map_block_the_radio_until_a_robot_walks_through_the_door(
    tb_name,
):
    office = os.path.join(REPO, "testbed", "experiments", "maps", "office.png")
    # Two rooms side by side, 5 m apart, range 8 m: the wall between them blocks the link.
    up = tb("net", "up", tb_name, "--robots", "2", "--positions", "2.5,5 7.5,5",
            "--comm-range", "8", "--range-model", "los", "--map", office)  # fmt: skip
    assert up.returncode == 0, up.stderr
    try:
        assert tb("net", "links", tb_name).stdout == ""
        # Robot 2 leaves its room by its door and walks the corridor to below robot 1's door.
        for x, y in ((7.5, 10.0), (4.0, 10.0)):
            assert tb("net", "move", tb_name, "r2", str(x), str(y)).returncode == 0
            assert tb("net", "links", tb_name).stdout == "", (x, y)  # still behind walls
        assert tb("net", "move", tb_name, "r2", "2.5", "10").returncode == 0
        assert tb("net", "links", tb_name).stdout == "1 2\n"  # through robot 1's door
    finally:
        tb("net", "down", tb_name)
    _one_line_error(
        tb("net", "up", tb_name, "--robots", "2", "--comm-range", "8", "--range-model", "los"),
        "needs --map",
    )
    _one_line_error(
        tb("net", "up", tb_name, "--robots", "2", "--comm-range", "8", "--range-model", "los",
           "--map", "/nonexistent.png"),
        "does not exist",
    )  # fmt: skip


def test_net_up_view_follows_moves_and_goes_down_with_the_network(tb_name):
    import json
    import socket
    import urllib.request

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]

    def frame():
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/live", timeout=5) as stream:
            for line in stream:
                if line.startswith(b"data: "):
                    return json.loads(line[6:])

    up = tb("net", "up", tb_name, "--robots", "3", "--layout", "chain", "--spacing", "8",
            "--comm-range", "10", "--routing", "oracle", "--view", str(port))  # fmt: skip
    assert up.returncode == 0, up.stderr
    try:
        deadline = time.monotonic() + 10
        first = None
        while first is None and time.monotonic() < deadline:
            try:
                first = frame()
            except OSError:
                time.sleep(0.2)
        assert first["links"] == [[1, 2], [2, 3]] and first["positions"][4] == 16.0
        assert tb("net", "move", tb_name, "r3", "16", "40").returncode == 0
        # The view sees the move at its next frame: a loaded machine may take a while.
        deadline = time.monotonic() + 10
        while (moved := frame())["links"] != [[1, 2]] and time.monotonic() < deadline:
            time.sleep(0.2)
        assert moved["links"] == [[1, 2]] and moved["positions"][5] == 40.0
        routes = json.loads(urllib.request.urlopen(
            f"http://127.0.0.1:{port}/api/routes?to=1", timeout=5).read())  # fmt: skip
        assert routes == {"2": 1, "3": None}
    finally:
        assert tb("net", "down", tb_name).returncode == 0
    with pytest.raises(OSError):
        urllib.request.urlopen(f"http://127.0.0.1:{port}/api/run", timeout=2)


def test_exec_passes_exit_status_through(tb_name):
    assert tb("net", "up", tb_name, "--robots", "2", "--comm-range", "10").returncode == 0
    try:
        assert tb("net", "exec", tb_name, "r2", "--", "sh", "-c", "exit 7").returncode == 7
        r = tb("net", "exec", tb_name, "r2", "--", "ip", "-br", "addr", "show", "wlan0")
        assert r.returncode == 0 and "10.0.0.2/32" in r.stdout
        r = tb("net", "exec", tb_name, "r3", "--", "true")
        assert r.returncode == 2 and "r1..r2" in r.stderr
    finally:
        tb("net", "down", tb_name)


def test_the_hint_net_up_prints_works_with_the_default_routing(tb_name):
    """`net up` without --routing runs AODV (the default of run and sweep files too), so the
    ping it suggests answers (it once defaulted to no routing: "Network is unreachable")."""
    up = tb("net", "up", tb_name, "--robots", "2", "--comm-range", "10")
    try:
        assert up.returncode == 0 and "routing aodv" in up.stdout, up.stderr
        hint = up.stdout.split("try: ", 1)[1].split()
        assert hint[:6] == ["testbed", "net", "exec", tb_name, "r1", "--"]
        r = tb(*hint[1:6], "ping", "-c1", "-W5", *hint[7:])
        assert r.returncode == 0 and "1 received" in r.stdout, r.stdout + r.stderr
    finally:
        tb("net", "down", tb_name)


def _one_line_error(r: subprocess.CompletedProcess, *words: str) -> None:
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert "Traceback" not in r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    for w in words:
        assert w in lines[0], lines[0]


def test_name_in_use_is_refused_and_left_intact(tb_name):
    assert tb("net", "up", tb_name, "--robots", "2", "--comm-range", "10").returncode == 0
    try:
        _one_line_error(tb("net", "up", tb_name, "--robots", "3", "--comm-range", "10"), "in use")
        assert tb("net", "links", tb_name).stdout == "1 2\n", "the first testbed is untouched"
    finally:
        tb("net", "down", tb_name)


# Runs its arguments as uid 65534 in a mount namespace of its own, where every directory the
# caller names (the checkout, the interpreter's) is readable to that user at its own path: a
# checkout in a 0700 directory (a home on Debian 13, `mktemp -d`) is otherwise unreadable to
# anyone else, and the command would fail on an import before it could say "not root". The
# topmost ancestor that user cannot enter is covered by a 0755 tmpfs holding only the paths
# down to bind mounts of the named directories; nothing outside the namespace changes.
AS_NOBODY = r"""
set -eu
nobody() { setpriv --reuid=65534 --regid=65534 --clear-groups "$@"; }
keep=()
while [ "$1" != -- ]; do keep+=("$1"); shift; done; shift
stage=$(mktemp -d /dev/shm/tb-nobody.XXXXXX)
trap 'umount -R "$stage" 2>/dev/null || true; rmdir "$stage"/* "$stage" 2>/dev/null || true' EXIT
covered=()
for dir in "${keep[@]}"; do
    p=""
    for part in $(echo "$dir" | tr / ' '); do
        p=$p/$part
        nobody test -x "$p" && continue
        i=${#covered[@]}; mkdir "$stage/$i"; mount --bind "$dir" "$stage/$i"
        covered+=("$p|$dir|$stage/$i")
        break
    done
done
for c in "${covered[@]}"; do
    top=${c%%|*}; rest=${c#*|}; dir=${rest%%|*}; from=${rest#*|}
    mountpoint -q "$top" && [ "$(stat -c %a "$top")" = 755 ] ||
        mount -t tmpfs -o mode=0755 tb-nobody "$top"
    mkdir -p "$dir"; mount --move "$from" "$dir"
done
nobody "$@"
"""


def _as_nobody(argv: list[str], keep: list[str], **kw) -> subprocess.CompletedProcess:
    script = [
        "unshare",
        "--mount",
        "--propagation",
        "private",
        "bash",
        "-c",
        AS_NOBODY,
        "as-nobody",
    ]
    return subprocess.run([*script, *keep, "--", *argv], **kw)


def test_not_root_is_a_one_line_error(tb_name):
    for tool in ("setpriv", "unshare", "mountpoint"):
        if shutil.which(tool) is None:
            pytest.skip(f"{tool} (util-linux) not installed")
    python_home = os.path.dirname(os.path.dirname(os.path.realpath(sys.executable)))
    r = _as_nobody(
        [*TESTBED, "net", "up", tb_name, "--robots", "2", "--comm-range", "10"],
        keep=[REPO, python_home],
        capture_output=True, text=True, cwd=REPO, env={**os.environ, "HOME": "/tmp"},
    )  # fmt: skip
    _one_line_error(r, "root", "sudo")
    assert not [ns for ns in netns.list_names() if tb_name in ns]


def test_missing_tool_is_a_one_line_error(tb_name, tmp_path):
    bindir = tmp_path / "bin"
    bindir.mkdir()
    os.symlink(shutil.which("ip"), bindir / "ip")  # ip, but no babeld on this PATH
    env = {**os.environ, "PATH": str(bindir)}
    r = tb("net", "up", tb_name, "--robots", "2", "--comm-range", "10", "--routing", "babel",
           env=env)  # fmt: skip
    _one_line_error(r, "babeld", "package(s) babeld")
    assert not [ns for ns in netns.list_names() if tb_name in ns]


OWNER = textwrap.dedent(
    """
    import sys, time
    from topology.network import Network
    from topology.spec import NetworkSpec
    spec = NetworkSpec(name=sys.argv[1], positions=((0, 0), (8, 0), (16, 0)),
                       comm_range=10.0, routing="babel", capture_dir=sys.argv[2])
    net = Network(spec)
    net.up()
    print("up", flush=True)
    time.sleep(600)
    """
)


def test_sigkilled_owner_then_clean_leaves_nothing(tb_name, tmp_path):
    owner = subprocess.Popen(
        [sys.executable, "-c", OWNER, tb_name, str(tmp_path / "pcaps")],
        cwd=REPO, stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert owner.stdout.readline().strip() == "up"
        st = state.read(tb_name)
        pids = [(p.pid, p.start) for p in st.processes]
        assert {p.role for p in st.processes} == {"babel", "tcpdump"} and len(pids) == 6
        # A persistent testbed of someone else's must survive our clean.
        bystander = tb_name[:-1] + ("z" if tb_name[-1] != "z" else "y")
        assert tb("net", "up", bystander, "--robots", "1", "--comm-range", "5").returncode == 0
        try:
            assert tb("clean").stdout.strip() == "nothing to clean", "owner still alive"
            owner.send_signal(signal.SIGKILL)
            owner.wait()
            assert state.read(tb_name).abandoned()
            r = tb("clean")
            assert r.returncode == 0 and tb_name in r.stdout and bystander not in r.stdout
            assert netns.exists(names.medium_ns(bystander))
        finally:
            tb("net", "down", bystander)
    finally:
        if owner.poll() is None:
            owner.kill()
            owner.wait()
    assert not [ns for ns in netns.list_names() if tb_name in ns]
    assert not [pid for pid, start in pids if state.is_alive(pid, start)]
    assert state.read(tb_name) is None
    assert not os.path.exists(state.run_dir(tb_name))
    assert processes.pids_in_namespace(names.medium_ns(tb_name)) == []
    # The pcaps and the daemons' logs survive the clean-up: results are never lost.
    assert sorted(os.listdir(tmp_path / "pcaps")) == ["daemons", "r1.pcap", "r2.pcap", "r3.pcap"]
    kept = os.listdir(tmp_path / "pcaps" / "daemons")
    assert {f"r{k}.babel.log" for k in (1, 2, 3)} <= set(kept)


def test_impair_one_link_by_hand_and_clear_it(tb_name):
    assert tb("net", "up", tb_name, "--robots", "3", "--layout", "chain", "--spacing", "5",
              "--comm-range", "6").returncode == 0  # fmt: skip
    try:
        for k, others in ((1, (2,)), (2, (1, 3)), (3, (2,))):
            for o in others:
                tb("net", "exec", tb_name, f"r{k}", "--", "ip", "route", "add",
                   f"10.0.0.{o}/32", "dev", "wlan0", "scope", "link")  # fmt: skip

        def ping(src, dst) -> int:
            return tb("net", "exec", tb_name, f"r{src}", "--", "ping", "-c2", "-W1",
                      f"10.0.0.{dst}").returncode  # fmt: skip

        assert ping(1, 2) == 0 and ping(2, 3) == 0
        assert tb("net", "impair", tb_name, "r1", "r2", "--loss", "100").returncode == 0
        assert ping(1, 2) != 0, "link 1-2 drops everything"
        assert ping(2, 3) == 0, "link 2-3 is untouched"
        # The setting belongs to the link: it holds after the robots part and meet again.
        assert tb("net", "move", tb_name, "r1", "-50", "0").returncode == 0
        assert tb("net", "move", tb_name, "r1", "0", "0").returncode == 0
        assert ping(1, 2) != 0
        assert tb("net", "impair", tb_name, "r1", "r2").returncode == 0  # no option: clear
        assert ping(1, 2) == 0
        r = tb("net", "impair", tb_name, "r1", "r1", "--loss", "5")
        assert r.returncode == 2 and "two different robots" in r.stderr
    finally:
        tb("net", "down", tb_name)
