"""A robot's messenger, alone, run inside a robot namespace by tests/integration/test_middleware.py.

`MIDDLEWARE ME PORT TIMEOUT_MS listen`: open robot ME's messenger on its address and print
each message received, one line of text each, until killed.
`MIDDLEWARE ME PORT TIMEOUT_MS send TO`: open it, connect to robot TO, then for each line
read on stdin send that line to TO and print one JSON line: the line sent, what send()
returned, the wall seconds it took and the messenger's counters. Before each send it prints
`sending`, so that a send that never returns shows.
"""

import json
import select
import sys
import time

from node.messaging import open_messenger
from topology.names import robot_addr


def main(argv: list[str]) -> None:
    middleware, me, port, timeout_ms, mode, *rest = argv
    m = open_messenger(
        middleware, me=int(me), bind_addr=robot_addr(int(me)), port=int(port),
        addr_of=robot_addr, team=(1, 2, 3), send_timeout_ms=int(timeout_ms),
        reconnect_ms=(50, 500),
    )  # fmt: skip
    print("ready", flush=True)
    if mode == "listen":
        while True:
            select.select([m.fileno()], [], [], 0.5)
            for data in m.receive():
                print(data.decode(), flush=True)
    to = int(rest[0])
    m.connect(to)
    for line in sys.stdin:
        data = line.strip().encode()
        print("sending", flush=True)
        t0 = time.monotonic()
        ok = m.send(to, data)
        took = time.monotonic() - t0
        print(json.dumps({"data": data.decode(), "ok": ok, "s": took,
                          "stats": m.stats.as_dict()}), flush=True)  # fmt: skip


if __name__ == "__main__":
    main(sys.argv[1:])
