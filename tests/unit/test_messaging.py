"""The goal messages' middlewares (node.messaging): the registry, a missing package named in
one line, the counters, and each messenger's sends on loopback (bounded, or for
zeromq-reqrep, measured while they wait)."""

import ast
import importlib.util
import socket
import subprocess
import sys
import threading
import time

import pytest

from node import messaging, wire
from node.messaging import MIDDLEWARES, REGISTRY, MiddlewareUnavailable, open_messenger
from node.messaging.arrivals import LATE_STEPS, Arrivals
from node.messaging.stats import COUNTERS, MessengerStats

AVAILABLE = [m for m in MIDDLEWARES if messaging.unavailable(m) is None]
TIMEOUT_MS = 50


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _pair(name: str, port: int, listening: tuple[int, ...] = (1, 2)):
    """Messengers of robots 1 and 2 on 127.0.0.1 and 127.0.0.2, the same port, as in a run
    (only those in `listening` are made). Cyclone DDS binds its sockets to every address:
    its two robots share 127.0.0.1 and one network stack, told apart by participant index."""
    dds = name == "dds"
    return {
        k: open_messenger(
            name,
            me=k,
            bind_addr="127.0.0.1" if dds else f"127.0.0.{k}",
            port=port,
            addr_of=(lambda j: "127.0.0.1") if dds else (lambda j: f"127.0.0.{j}"),
            team=(1, 2),
            send_timeout_ms=TIMEOUT_MS,
            reconnect_ms=(10, 100),
            **({"shared_stack": 2} if dds else {}),
        )  # fmt: skip
        for k in listening
    }


def test_the_registry_holds_every_middleware_once_and_the_default():
    assert tuple(REGISTRY) == MIDDLEWARES
    assert len(set(MIDDLEWARES)) == len(MIDDLEWARES)
    assert messaging.DEFAULT == "nanomsg" and "nanomsg" in AVAILABLE
    for name in ("nanomsg", "zeromq", "zeromq-reqrep"):
        if name in AVAILABLE:
            assert messaging.messenger_class(name).name == name


@pytest.mark.parametrize("name", MIDDLEWARES)
def test_a_missing_package_is_named_in_one_line(name, monkeypatch):
    entry = REGISTRY[name]
    monkeypatch.setitem(sys.modules, entry.imports, None)  # import fails as if not installed
    monkeypatch.delitem(sys.modules, entry.module, raising=False)
    with pytest.raises(MiddlewareUnavailable) as e:
        open_messenger(name, me=1, bind_addr="127.0.0.1", port=0, addr_of=str, team=(1,),
                       send_timeout_ms=10, reconnect_ms=(10, 10))  # fmt: skip
    text = str(e.value)
    assert "\n" not in text
    assert f"--middleware {name} needs the Python package {entry.package}," in text
    assert messaging.unavailable(name) == text


@pytest.mark.parametrize("name", MIDDLEWARES)
def test_every_entry_names_modules_and_a_class_that_exist(name):
    """Read from the source, so a middleware whose package is missing here is checked too."""
    entry = REGISTRY[name]
    for module, cls in ((entry.module, entry.cls), (entry.map_topic, None)):
        if module is None:
            continue
        spec = importlib.util.find_spec(module)
        assert spec is not None and spec.origin, module
        if cls:
            tree = ast.parse(open(spec.origin).read())
            assert cls in {n.name for n in tree.body if isinstance(n, ast.ClassDef)}
    with pytest.raises(MiddlewareUnavailable, match="unknown"):
        messaging.messenger_class("mqtt")


def test_every_framing_of_the_registry_is_parsed_by_the_capture_analysis():
    from node.messaging import maps
    from testbed.analysis import mwframing, pcapmetrics

    parsed = set(mwframing.FRAMINGS) | pcapmetrics.DATAGRAM_FRAMINGS
    assert {e.framing for e in REGISTRY.values()} <= parsed
    assert maps.PUBSUB_MIDDLEWARES == ("zenoh", "dds")


def test_stats_count_sends_and_a_send_still_inside():
    s = MessengerStats()
    t = s.send_started()
    time.sleep(0.02)
    s.send_ended(t, True)
    s.send_ended(s.send_started(), False)
    stuck = s.send_started()
    time.sleep(0.05)
    d = s.as_dict()
    assert tuple(d)[: len(COUNTERS)] == COUNTERS
    assert (d["sent"], d["failed"], d["sending"]) == (1, 1, 1)
    assert d["blocked_max_s"] >= 0.05 and d["blocked_s"] >= 0.07  # the stuck send counts
    s.send_ended(stuck, False)
    assert s.as_dict()["sending"] == 0 and s.failed == 2


def test_arrivals_count_duplicates_and_late_messages():
    a = Arrivals()
    a.note(2, 1, sent_step=10, step=10)
    a.note(2, 1, sent_step=10, step=11)  # delivered twice
    a.note(3, 1, sent_step=10, step=10)  # another sender's number 1
    a.note(2, 2, sent_step=10, step=10 + LATE_STEPS + 1)  # late
    a.note(3, None, sent_step=5, step=5)  # no number: not judged for duplicates
    assert a.as_dict() == {"messages": 5, "duplicates": 1, "late": 1,
                           "delay_steps_max": LATE_STEPS + 1}  # fmt: skip


def test_messages_carry_their_number_and_older_ones_without_it_still_parse():
    m = wire.parse_msg(wire.goal_msg(2, 10, (1.0, 2.0), 3.5, n=7), 5)
    assert m["n"] == 7
    assert wire.parse_msg(wire.replan_msg(1, 11, (4.0, 4.0), 8), 5)["n"] == 8
    assert wire.parse_msg(b'{"k": "replan", "from": 1, "step": 1, "goal": [1, 2]}', 5)["n"] is None
    for bad in ("0", "-1", '"7"', "true", "1.5"):
        with pytest.raises(ValueError, match="number"):
            wire.parse_msg(
                f'{{"k": "replan", "from": 1, "step": 1, "goal": [1, 2], "n": {bad}}}'.encode(), 5
            )


def _receive(m, want: int, timeout: float = 5.0) -> list[bytes]:
    import select

    got: list[bytes] = []
    deadline = time.monotonic() + timeout
    while len(got) < want and time.monotonic() < deadline:
        select.select([m.fileno()], [], [], 0.1)
        got += m.receive()
    return got


@pytest.mark.parametrize("name", AVAILABLE)
def test_a_message_goes_from_one_robot_to_another_and_is_counted(name):
    ms = _pair(name, _free_port())
    try:
        ms[1].connect(2)
        got: list[bytes] = []
        rx = threading.Thread(target=lambda: got.extend(_receive(ms[2], 1)))
        rx.start()  # zeromq-reqrep's send returns only once robot 2 has taken the message
        deadline = time.monotonic() + 5
        while not ms[1].send(2, b"hello") and time.monotonic() < deadline:
            pass
        rx.join()
        assert got == [b"hello"]
        s1, s2 = ms[1].stats.as_dict(), ms[2].stats.as_dict()
        assert s1["sent"] == 1 and s2["received"] == 1 and s1["sending"] == 0
        assert 0 < s1["blocked_max_s"] <= s1["blocked_s"]
    finally:
        for m in ms.values():
            m.close()
            m.close()  # idempotent


# Messages queued, without a connection, before sends give up: nng's send buffer holds 8
# (docs/middleware.md); ZMQ_IMMEDIATE queues none.
QUEUED_UNCONNECTED = {"nanomsg": 8, "zeromq": 0}


@pytest.mark.parametrize("name", [m for m in AVAILABLE if m in QUEUED_UNCONNECTED])
def test_a_send_to_a_teammate_that_is_not_there_gives_up_after_the_timeout(name):
    ms = _pair(name, _free_port(), listening=(1,))
    queued = QUEUED_UNCONNECTED[name]
    try:
        took, oks = [], []
        for _ in range(queued + 3):
            t0 = time.monotonic()
            oks.append(ms[1].send(2, b"anyone?"))
            took.append(time.monotonic() - t0)
        assert oks == [True] * queued + [False] * 3
        s = ms[1].stats.as_dict()
        assert (s["sent"], s["failed"]) == (queued, 3)
        failed = took[queued:]
        assert all(TIMEOUT_MS / 1000 * 0.5 <= t <= TIMEOUT_MS / 1000 + 0.5 for t in failed), took
        assert s["blocked_max_s"] == pytest.approx(max(took), abs=0.01)
    finally:
        ms[1].close()


@pytest.mark.skipif("zeromq-reqrep" not in AVAILABLE, reason="pyzmq is not installed")
def test_zeromq_reqrep_waits_for_a_reply_that_never_comes_until_closed():
    ms = _pair("zeromq-reqrep", _free_port(), listening=(1,))
    result: list[bool] = []
    sender = threading.Thread(target=lambda: result.append(ms[1].send(2, b"anyone?")))
    sender.start()
    sender.join(1.0)
    try:
        assert sender.is_alive() and not result  # still waiting, 20 timeouts later
        s = ms[1].stats.as_dict()
        assert s["sending"] == 1 and s["blocked_s"] >= 1.0 and s["sent"] == s["failed"] == 0
    finally:
        ms[1].close()  # ends the wait
    sender.join(5.0)
    assert result == [False] and ms[1].stats.failed == 1


def test_a_run_with_a_missing_middleware_package_refuses_in_one_line(tmp_path):
    out = tmp_path / "run"
    code = (
        "import sys; sys.modules['zmq'] = None; "
        "sys.argv = ['testbed', 'run', '--robots', '2', '--comm-range', '5', "
        f"'--middleware', 'zeromq', '--out', {str(out)!r}]; "
        "from testbed.console import main; sys.exit(main())"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and "Traceback" not in r.stderr
    assert "--middleware zeromq needs the Python package pyzmq" in r.stderr
    assert not out.exists()  # refused before anything was made


def test_result_json_gets_the_middleware_each_robots_counters_and_the_teams_totals():
    from testbed.run.results import messaging as totals

    def summary(sent, blocked_max, late):
        return {
            "messenger": {"sent": sent, "failed": 1, "received": 2, "blocked_s": 0.25,
                          "blocked_max_s": blocked_max, "sending": 0},
            "arrivals": {"messages": 2, "duplicates": 0, "late": late, "delay_steps_max": late},
        }  # fmt: skip

    got = totals("zeromq", {"r1": summary(3, 0.125, 1), "r2": summary(4, 0.5, 0), "r3": {}})
    assert got["middleware"] == "zeromq"
    assert got["robots"]["r3"] is None  # left no summary (crashed)
    assert got["robots"]["r1"]["sent"] == 3 and got["robots"]["r1"]["late"] == 1
    team = got["team"]
    assert (team["robots"], team["sent"], team["failed"], team["received"]) == (2, 7, 2, 4)
    assert (team["blocked_s"], team["blocked_max_s"], team["late"]) == (0.5, 0.5, 1)
    assert (team["delay_steps_max"], team["duplicates"], team["sending"]) == (1, 0, 0)


@pytest.mark.skipif("zeromq" not in AVAILABLE, reason="pyzmq is not installed")
@pytest.mark.parametrize("scale", [1.0, 10.0])
def test_zeromq_sockets_keep_the_dilated_intervals_and_the_recommended_options(scale):
    import zmq

    from node.timing import RobotTimings

    t = RobotTimings(time_scale=scale)
    kw = dict(me=1, bind_addr="127.0.0.1", port=_free_port(), addr_of=lambda j: "127.0.0.1",
              team=(1, 2), send_timeout_ms=t.goal_send_timeout_ms,
              reconnect_ms=(t.goal_reconnect_min_ms, t.goal_reconnect_max_ms))  # fmt: skip
    bounded, naive = open_messenger("zeromq", **kw), None
    try:
        s = bounded._peer(2).sock
        got = [s.getsockopt(o) for o in (zmq.SNDTIMEO, zmq.IMMEDIATE, zmq.SNDHWM, zmq.LINGER,
                                         zmq.RECONNECT_IVL, zmq.RECONNECT_IVL_MAX)]  # fmt: skip
        assert got == [round(50 / scale), 1, 8, 0, round(50 / scale), round(500 / scale)]
        naive = open_messenger("zeromq-reqrep", **dict(kw, port=_free_port()))
        s = naive._peer(2).sock
        got = [s.getsockopt(o) for o in (zmq.SNDTIMEO, zmq.RCVTIMEO, zmq.IMMEDIATE,
                                         zmq.RECONNECT_IVL)]  # fmt: skip
        assert got == [-1, -1, 0, round(50 / scale)]  # no bound: the naive variant
    finally:
        for m in (bounded, naive):
            if m is not None:
                m.close()
