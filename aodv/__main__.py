"""`python -m aodv --robot r3 --iface wlan0 [--time-scale K] [--stats PATH] [--log-level L]`"""

from __future__ import annotations

import argparse
import ipaddress
import logging
import os
import sys

from topology.argtypes import number

EXIT_USAGE = 2
EXIT_FAILURE = 1


class RobotFormatter(logging.Formatter):
    """Puts the robot's name on every line, traceback lines included."""

    def __init__(self, robot: str) -> None:
        super().__init__("%(asctime)s %(name)s %(levelname)s %(message)s")
        self.robot = robot

    def format(self, record: logging.LogRecord) -> str:
        text = super().format(record)
        return "\n".join(f"{self.robot} {line}" for line in text.splitlines())


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, exit status 2
        print(f"aodv: error: {message}", file=sys.stderr)
        sys.exit(EXIT_USAGE)


def _network(text: str) -> str:
    try:
        return str(ipaddress.IPv4Network(text))
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = _Parser(
        prog="python -m aodv",
        description="AODV (RFC 3561) routing daemon for one robot's network namespace.",
    )
    p.add_argument("--robot", required=True, help="robot name, on every log line (e.g. r3)")
    p.add_argument("--iface", default="wlan0", help="radio interface (default wlan0)")
    p.add_argument(
        "--time-scale",
        type=number(float, "time scale", above=0),
        default=1.0,
        help="run every protocol timer K times faster (default 1)",
    )
    p.add_argument("--stats", metavar="PATH", help="statistics JSON, rewritten every second")
    p.add_argument(
        "--log-level",
        default="info",
        choices=["debug", "info", "warning", "error"],
        help="default info",
    )
    p.add_argument(
        "--net",
        type=_network,
        default="10.0.0.0/16",
        help="the ad hoc network (default 10.0.0.0/16)",
    )
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(RobotFormatter(args.robot))
    logging.basicConfig(level=args.log_level.upper(), handlers=[handler])
    if os.geteuid() != 0:
        print("aodv: error: needs root (CAP_NET_ADMIN) in the robot's namespace", file=sys.stderr)
        return EXIT_USAGE
    from aodv.daemon import Daemon
    from aodv.kernel import KernelError
    from aodv.params import Params

    if args.stats:
        parent = os.path.dirname(os.path.abspath(args.stats))
        if not os.path.isdir(parent):
            print(f"aodv: error: no directory for --stats: {parent}", file=sys.stderr)
            return EXIT_USAGE
    try:
        return Daemon(
            args.robot, args.iface, Params(time_scale=args.time_scale), args.stats, args.net
        ).run()
    except KernelError as e:
        print(f"aodv: error: {e}", file=sys.stderr)
        return EXIT_USAGE if "no interface" in str(e) or "no IPv4" in str(e) else EXIT_FAILURE


if __name__ == "__main__":
    sys.exit(main())
