"""A tiny UDP prober run inside robot namespaces by the integration tests.

`listen PORT OUT`: record "SRC PAYLOAD" for every datagram received on wlan0 until SIGTERM.
`send PORT DST [DST ...] [--count N] [--gap S]`: send datagrams through wlan0 (DST may be
255.255.255.255 for a broadcast); the payload names the sender and a sequence number.
"""

import argparse
import signal
import socket
import sys
import time

SO_BINDTODEVICE = 25
SO_RCVBUFFORCE = 33  # root may exceed rmem_max
RCVBUF = 8 << 20  # a listener descheduled on a loaded machine must not drop what arrived


def _socket() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
    s.setsockopt(socket.SOL_SOCKET, SO_BINDTODEVICE, b"wlan0")
    return s


def listen(port: int, out: str) -> None:
    s = _socket()
    s.setsockopt(socket.SOL_SOCKET, SO_RCVBUFFORCE, RCVBUF)
    s.bind(("0.0.0.0", port))
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    with open(out, "w", buffering=1) as f:
        f.write("ready\n")
        while True:
            data, (src, _) = s.recvfrom(2048)
            f.write(f"{src} {data.decode(errors='replace')}\n")


def send(port: int, dsts: list[str], count: int, gap: float, tag: str) -> None:
    s = _socket()
    for n in range(count):
        for dst in dsts:
            try:
                s.sendto(f"{tag}:{n}".encode(), (dst, port))
            except OSError:
                pass  # no route or no neighbour: the test counts what arrives
        if gap:
            time.sleep(gap)


def main() -> None:
    p = argparse.ArgumentParser()
    sub = p.add_subparsers(dest="cmd", required=True)
    lp = sub.add_parser("listen")
    lp.add_argument("port", type=int)
    lp.add_argument("out")
    sp = sub.add_parser("send")
    sp.add_argument("port", type=int)
    sp.add_argument("dst", nargs="+")
    sp.add_argument("--count", type=int, default=1)
    sp.add_argument("--gap", type=float, default=0.0)
    sp.add_argument("--tag", default="x")
    a = p.parse_args()
    if a.cmd == "listen":
        listen(a.port, a.out)
    else:
        send(a.port, a.dst, a.count, a.gap, a.tag)


if __name__ == "__main__":
    main()
