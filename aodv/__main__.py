"""`python -m aodv --robot r3 --iface wlan0 [--time-scale K] [--profile rfc|ns3]
[--no-local-repair] [--set NAME=VALUE ...] [--stats PATH] [--stats-period S] [--state PATH]
[--log-level L] [--net NET] [--netns NAME]`

`--netns NAME`: the daemon enters the named network namespace (/run/netns/NAME, as `ip netns`
names it) itself before it makes any socket, so that it can be started without `ip netns exec`
(a fork and exec of ip, and a mount namespace per daemon, for nothing the daemon needs: it
reads no /sys). build/tb-aodv takes the same option.
"""

from __future__ import annotations

import argparse
import ipaddress
import logging
import logging.handlers
import os
import queue
import sys
from dataclasses import fields, replace
from typing import NoReturn

from aodv.params import PROFILES, Params, profile
from aodv.stats import STATS_PERIOD
from common.argtypes import checked, number
from common.errors import EXIT_FAILURE, EXIT_USAGE
from topology.names import NETWORK


class RobotFormatter(logging.Formatter):
    """Puts the robot's name on every line, traceback lines included."""

    def __init__(self, robot: str) -> None:
        super().__init__("%(asctime)s %(name)s %(levelname)s %(message)s")
        self.robot = robot

    def format(self, record: logging.LogRecord) -> str:
        text = super().format(record)
        return "\n".join(f"{self.robot} {line}" for line in text.splitlines())


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:  # one line, exit status 2
        print(f"aodv: error: {message}", file=sys.stderr)
        sys.exit(EXIT_USAGE)


@checked
def _network(text: str) -> str:
    return str(ipaddress.IPv4Network(text))


@checked
def _netns_name(text: str) -> str:
    """A name under /run/netns, as `ip netns` takes it: not empty, not . or .., no slash."""
    if text in ("", ".", "..") or "/" in text:
        raise ValueError(f"not a network namespace name: {text!r}")
    return text


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
    p.add_argument(
        "--profile",
        choices=sorted(PROFILES),
        default="rfc",
        help="parameter set: rfc (RFC 3561 section 10 with its notes, default) or ns3 "
        "(ns-3's AODV defaults, to compare with ns-3 studies)",
    )
    p.add_argument(
        "--no-local-repair",
        action="store_true",
        help="turn local repair (RFC 3561 6.12) off; the ns3 profile has it off anyway",
    )
    p.add_argument(
        "--set",
        metavar="NAME=VALUE",
        action="append",
        default=[],
        help="override one parameter of the profile (a field of aodv.params.Params, e.g. "
        "my_route_timeout_ms=11200); the section 10 constraints are checked",
    )
    p.add_argument("--stats", metavar="PATH", help="statistics JSON (see --stats-period)")
    p.add_argument(
        "--stats-period",
        type=number(float, "stats period", minimum=0),
        default=STATS_PERIOD,
        metavar="SECONDS",
        help="wall seconds between rewrites of --stats (default 1); 0: written only when the "
        "daemon is ready, on SIGUSR1 and as it stops (an idle daemon then sleeps)",
    )
    p.add_argument(
        "--state",
        metavar="PATH",
        help="counter file that survives a restart (RFC 6.13: sequence number and RREQ ID "
        "resume above it, and its presence makes a start a reboot); without it only "
        "routes left in the kernel tell a restart",
    )
    p.add_argument(
        "--log-level",
        default="info",
        choices=["debug", "info", "warning", "error"],
        help="default info",
    )
    p.add_argument(
        "--net",
        type=_network,
        default=NETWORK,
        help=f"the ad hoc network (default {NETWORK})",
    )
    p.add_argument(
        "--netns",
        type=_netns_name,
        metavar="NAME",
        help="enter the network namespace NAME (/run/netns/NAME) before anything else; "
        "without it the daemon runs in the namespace it was started in",
    )
    return p.parse_args(argv)


def build_params(args: argparse.Namespace) -> Params:
    """The profile, its overrides and --no-local-repair; ValueError says what is wrong."""
    params = profile(args.profile, args.time_scale)
    changes: dict = {"local_repair": False} if args.no_local_repair else {}
    types = {f.name: f.type for f in fields(Params)}
    for item in args.set:
        name, sep, text = item.partition("=")
        if not sep or name not in types or name == "time_scale":
            raise ValueError(f"--set {item!r}: not NAME=VALUE with NAME a field of Params")
        kind = types[name]
        try:
            if "bool" in kind:
                if text not in ("true", "false"):
                    raise ValueError
                changes[name] = text == "true"
            else:
                changes[name] = (float if "float" in kind else int)(text)
        except ValueError:
            raise ValueError(f"--set {item!r}: {name} takes {kind.split()[0]}") from None
    params = replace(params, **changes)
    problems = params.problems()
    if problems:
        raise ValueError(f"parameters break RFC 3561: {'; '.join(problems)}")
    return params


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        params = build_params(args)
    except ValueError as e:
        print(f"aodv: error: {e}", file=sys.stderr)
        return EXIT_USAGE
    listener = _start_logging(args.robot, args.log_level)
    try:
        return _serve(args, params)
    finally:
        listener.stop()


def _start_logging(robot: str, level: str) -> logging.handlers.QueueListener:
    """Log lines go through a queue to a thread that writes them: the daemon's loop never
    waits on its log file (a write can wait on the file system's journal behind a disk
    that is busy with someone else's data)."""
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(RobotFormatter(robot))
    lines: queue.SimpleQueue[logging.LogRecord] = queue.SimpleQueue()
    queued = logging.handlers.QueueHandler(lines)
    queued.setFormatter(logging.Formatter("%(message)s"))  # the listener's handler adds the rest
    logging.basicConfig(level=level.upper(), handlers=[queued])
    listener = logging.handlers.QueueListener(lines, handler)
    listener.start()
    return listener


def _serve(args: argparse.Namespace, params: Params) -> int:
    if os.geteuid() != 0:
        print("aodv: error: needs root (CAP_NET_ADMIN) in the robot's namespace", file=sys.stderr)
        return EXIT_USAGE
    from aodv.daemon import Daemon
    from aodv.kernel import KernelError

    for option, path in (("--stats", args.stats), ("--state", args.state)):
        parent = os.path.dirname(os.path.abspath(path)) if path else None
        if parent and not os.path.isdir(parent):
            print(f"aodv: error: no directory for {option}: {parent}", file=sys.stderr)
            return EXIT_USAGE
    if args.netns:
        # Before the daemon makes any socket or thread: a socket belongs to the namespace
        # it was made in, a thread starts in its creator's.
        from topology.kernel import netns

        try:
            netns.enter(args.netns)
        except OSError as e:
            why = os.strerror(e.errno) if e.errno else str(e)
            print(f"aodv: error: network namespace {args.netns}: {why}", file=sys.stderr)
            return EXIT_USAGE
    try:
        return Daemon(
            args.robot, args.iface, params, args.stats, args.net, args.state, args.stats_period
        ).run()
    except KernelError as e:
        print(f"aodv: error: {e}", file=sys.stderr)
        return EXIT_USAGE if "no interface" in str(e) or "no IPv4" in str(e) else EXIT_FAILURE


if __name__ == "__main__":
    sys.exit(main())
