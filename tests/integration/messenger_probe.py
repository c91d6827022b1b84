"""One robot's messenger (node.messaging.zenoh or .dds) in its namespace, driven over stdio.

`python messenger_probe.py KIND ME PORT TEAM_SIZE`: makes the messenger as a robot does (its
address from topology.names, the send timeout and redial backoff from node.timing at time
scale 1), prints `{"up": true}`, then one JSON line per event:
  stdin `send J TEXT`  ->  {"sent": J, "ok": bool, "took": seconds}
  a message received   ->  {"received": TEXT}
It ends when stdin closes.
"""

import json
import os
import select
import sys
import time

from node.timing import RobotTimings
from topology.names import robot_addr


def make(kind: str, me: int, port: int, team: list[int]):
    t = RobotTimings()
    args = (me, robot_addr(me), port, robot_addr, team, t.goal_send_timeout_ms,
            (t.goal_reconnect_min_ms, t.goal_reconnect_max_ms))  # fmt: skip
    if kind == "zenoh":
        from node.messaging.zenoh import ZenohMessenger

        return ZenohMessenger(*args)
    from node.messaging.dds import DdsMessenger

    return DdsMessenger(*args)


def say(**event) -> None:
    print(json.dumps(event), flush=True)


def main() -> None:
    kind, me, port, n = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
    m = make(kind, me, port, list(range(1, n + 1)))
    for j in range(1, n + 1):
        if j != me:
            m.connect(j)
    say(up=True)
    stdin = sys.stdin.fileno()
    pending = b""
    try:
        while True:
            ready, _, _ = select.select([stdin, m.fileno()], [], [])
            if m.fileno() in ready:
                for data in m.receive():
                    say(received=data.decode())
            if stdin in ready:
                chunk = os.read(stdin, 4096)
                if not chunk:
                    return
                pending += chunk
                while b"\n" in pending:
                    line, pending = pending.split(b"\n", 1)
                    _, j, text = line.decode().split(" ", 2)
                    t0 = time.monotonic()
                    ok = m.send(int(j), text.encode())
                    say(sent=int(j), ok=ok, took=time.monotonic() - t0)
    finally:
        m.close()


if __name__ == "__main__":
    main()
