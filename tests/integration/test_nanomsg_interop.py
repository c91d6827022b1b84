"""A robot's nanomsg endpoint talks with Debian's libnanomsg tools (nanocat), both ways.

The robot's goal socket (node.messaging.nanomsg, pynng/nng) is used exactly as a robot uses it,
in one robot namespace; nanocat (libnanomsg) runs in another, one hop away over the emulated radio.
Messages are the robots' own goal messages, parsed by the robot's parser: so the wire protocol
is nanomsg's SP over TCP.
"""

import json
import os
import select
import subprocess
import sys
import textwrap
import uuid

import pytest

from node import wire
from testbed import PROJECT_ROOT
from topology.network import Network, destroy
from topology.spec import NetworkSpec

PORT = 5101

pytestmark = pytest.mark.skipif(
    subprocess.run(["which", "nanocat"], capture_output=True).returncode != 0,
    reason="nanocat (nanomsg-utils) is not installed",
)


@pytest.fixture
def net():
    name = "tn" + uuid.uuid4().hex[:6]
    spec = NetworkSpec(name=name, positions=((0.0, 0.0), (5.0, 0.0)), comm_range=10.0)
    try:
        with Network(spec) as n:
            # routing "none": one hop still needs a route to the neighbour's /32.
            for k, other in ((1, 2), (2, 1)):
                n.exec(k, ["ip", "route", "add", f"10.0.0.{other}/32", "dev", "wlan0"],
                       check=True)  # fmt: skip
            yield n
    finally:
        destroy(name)


def robot_python(net, code: str, timeout: float = 20.0) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=PROJECT_ROOT)
    return net.exec(
        1, [sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
        timeout=timeout, env=env,
    )  # fmt: skip


def test_nanocat_push_to_robot(net):
    msg = wire.goal_msg(2, 17, (3.25, 4.5), 2.0).decode()
    sender = net.spawn(
        2, ["nanocat", "--push", "--connect", f"tcp://10.0.0.1:{PORT}", "--data", msg,
            "--interval", "0.2"],
        role="test", stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    try:
        got = robot_python(
            net,
            f"""
            import json, select
            from node.messaging.nanomsg import NanomsgMessenger
            from node import wire
            g = NanomsgMessenger(1, "10.0.0.1", {PORT}, lambda k: f"10.0.0.{{k}}")
            select.select([g.fileno()], [], [], 15)
            data = g.receive()[0]
            print(json.dumps(wire.parse_msg(data, 5)))
            g.close()
            """,
        )
    finally:
        sender.kill()
        sender.wait()
    assert got.returncode == 0, got.stderr
    m = json.loads(got.stdout)
    assert m["k"] == "goal" and m["from"] == 2 and m["step"] == 17
    assert m["goal"] == [3.25, 4.5]


def test_robot_push_to_nanocat(net):
    receiver = net.spawn(
        2, ["nanocat", "--pull", "--bind", f"tcp://10.0.0.2:{PORT}", "--quoted"],
        role="test", stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
    )  # fmt: skip
    # The robot's socket stays open until nanocat printed the message: nng drops what is
    # still queued when a socket closes, and on a loaded machine its I/O thread may not have
    # written the message out within a fixed wait.
    env = dict(os.environ, PYTHONPATH=PROJECT_ROOT)
    robot = net.spawn(1, [sys.executable, "-c", textwrap.dedent(f"""
        import time
        from node.messaging.nanomsg import NanomsgMessenger
        from node import wire
        g = NanomsgMessenger(1, "10.0.0.1", {PORT}, lambda k: f"10.0.0.{{k}}", send_timeout_ms=200)
        for _ in range(50):
            if g.send(2, wire.goal_msg(1, 42, (1.5, 2.5), 3.0)):
                break
        else:
            raise SystemExit("could not send")
        print("sent", flush=True)
        time.sleep(60)
        """)], role="test", stdout=subprocess.PIPE, text=True, env=env)  # fmt: skip
    try:
        ready, _, _ = select.select([receiver.stdout], [], [], 30.0)
        assert ready, f"nanocat received nothing (the robot said {robot.poll()!r})"
        line = receiver.stdout.readline().strip()
        assert robot.poll() is None and robot.stdout.readline() == "sent\n"
    finally:
        for p in (robot, receiver):
            p.kill()
            p.wait()
    assert line.startswith('"') and line.endswith('"')
    text = line[1:-1].encode().decode("unicode_escape")
    m = wire.parse_msg(text.encode(), 5)
    assert m["k"] == "goal" and m["from"] == 1 and m["step"] == 42 and m["goal"] == (1.5, 2.5)
