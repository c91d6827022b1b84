"""The `testbed` command: networks by hand (`net ...`), runs, sweeps, reports, clean-up.

Every error the user can cause is one line on stderr and exit status 2 (testbed.errors); a
failure while working is one line and status 1. Tracebacks are for bugs only.
"""

import argparse
import importlib
import importlib.util
import logging
import os
import signal
import sys

from pyroute2.netlink.exceptions import NetlinkError

from testbed import netextra, runoptions
from testbed.errors import EXIT_USAGE, TestbedError, UsageError
from testbed.runconfig import NET_OPTIONS, network_fields
from topology.argtypes import number
from topology.spec import LAYOUTS, LOS_MODELS

log = logging.getLogger("testbed")


class Parser(argparse.ArgumentParser):
    """argparse, but a bad argument is a UsageError: one line, exit status 2."""

    def error(self, message: str):
        raise UsageError(f"{self.prog}: {message}")


def _robot_count(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"robot count must be a whole number, not {text!r}"
        ) from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"a testbed needs at least one robot, not {n}")
    return n


def _robot_ref(text: str) -> int:
    body = text[1:] if text[:1] in ("r", "R") else text
    if not body.isdigit() or int(body) < 1:
        raise argparse.ArgumentTypeError(f"robot must be written rK with K >= 1, not {text!r}")
    return int(body)


def _positions(text: str) -> list[tuple[float, float]]:
    out = []
    for item in text.replace(";", " ").split():
        try:
            x, y = (float(v) for v in item.split(","))
        except ValueError:
            raise argparse.ArgumentTypeError(f"position {item!r} is not X,Y") from None
        out.append((x, y))
    if not out:
        raise argparse.ArgumentTypeError("--positions is empty")
    return out


def _name(text: str) -> str:
    from topology.names import check_name

    try:
        return check_name(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


# -- net ---------------------------------------------------------------------------------------


NAME_HELP = "the testbed's name (as given to net up)"
ROBOT_HELP = "a robot, rK (K from 1)"


def _add_net(sub) -> None:
    net = sub.add_parser("net", help="bring a network up by hand, use it, take it down")
    nsub = net.add_subparsers(dest="net_cmd", required=True, parser_class=Parser)

    up = nsub.add_parser("up", help="build a testbed network and leave it running")
    up.add_argument("name", type=_name, help="the testbed's name (lowercase letters, digits)")
    up.add_argument("--robots", type=_robot_count, metavar="N",
                    help="robots (required, unless --mobility's file gives them)")  # fmt: skip
    up.add_argument("--layout", choices=LAYOUTS, help="where the robots stand (default chain)")
    up.add_argument("--spacing", type=number(float, "spacing", above=0), default=8.0, metavar="M",
                    help="distance between neighbours of --layout (metres; default 8)")  # fmt: skip
    up.add_argument("--positions", type=_positions, metavar='"X,Y X,Y ..."',
                    help="where the robots stand (metres; instead of --layout)")  # fmt: skip
    up.add_argument(
        "--map",
        metavar="PNG",
        help="walls for the los models (dark pixels); positions are metres on it (default none)",
    )
    up.add_argument("--capture", metavar="DIR", help="write one pcap per robot here (default none)")
    up.add_argument("--seed", type=int, default=None, metavar="S",
                    help="seed of --layout random (default: another layout each time)")  # fmt: skip
    for opt in NET_OPTIONS:  # comm range, radio, routing, impairments, time scale: as `run`'s
        runoptions.add_option(up, opt)
    up.add_argument(
        "--view",
        metavar="[HOST:]PORT",
        help="serve a live view of the network (127.0.0.1 unless a host is given; default none)",
    )
    netextra.add_up_arguments(up)
    netextra.add_parsers(nsub, sub, _name)

    ex = nsub.add_parser("exec", help="run a command in a robot's namespace")
    ex.add_argument("name", type=_name, help=NAME_HELP)
    ex.add_argument("robot", type=_robot_ref, help=ROBOT_HELP)
    ex.add_argument("command", nargs=argparse.REMAINDER, help="-- CMD ARG ...: what to run")

    mv = nsub.add_parser("move", help="move a robot; links follow before this returns")
    mv.add_argument("name", type=_name, help=NAME_HELP)
    mv.add_argument("robot", type=_robot_ref, help=ROBOT_HELP)
    mv.add_argument("x", type=number(float, "x"), help="new x (metres)")
    mv.add_argument("y", type=number(float, "y"), help="new y (metres)")

    im = nsub.add_parser("impair", help="impair one link (both directions), or clear it")
    im.add_argument("name", type=_name, help=NAME_HELP)
    im.add_argument("robot_a", type=_robot_ref, help="one end of the link: " + ROBOT_HELP)
    im.add_argument("robot_b", type=_robot_ref, help="the other end")
    for flag, unit, what in (
        ("--loss", "PCT", "packet loss (percent"), ("--delay", "MS", "delay (ms"),
        ("--jitter", "MS", "delay jitter (ms"), ("--rate", "KBIT", "rate limit (kbit/s"),
    ):  # fmt: skip
        im.add_argument(flag, type=number(float, flag[2:], minimum=0), default=0.0,
                        metavar=unit, help=f"{what}; default 0: none)")  # fmt: skip

    ln = nsub.add_parser("links", help="print the current links, one 'i j' pair per line")
    ln.add_argument("name", type=_name, help=NAME_HELP)

    dn = nsub.add_parser("down", help="tear a testbed network down")
    dn.add_argument("name", type=_name, help=NAME_HELP)

    nsub.add_parser("list", help="list the testbeds that are up")


def _start_net_view(net, bind: str) -> None:
    """The view of a `net up` network: a process of its own (testbed.view.netview), recorded
    with the testbed so that `net down` stops it."""
    import subprocess

    log = open(os.path.join(net.state_dir, "view.log"), "w")  # noqa: SIM115 (the child's)
    proc = subprocess.Popen(
        [sys.executable, "-m", "testbed.view.netview", net.name, bind],
        stdout=log, stderr=subprocess.STDOUT, start_new_session=True,
    )  # fmt: skip
    net.adopt_host_process(proc, "view")
    print(f"  live view: http://{bind if ':' in bind else '127.0.0.1:' + bind}/")


def _start_positions(args) -> list:
    """Where `net up` puts the robots: --positions, or --layout's pattern."""
    from topology.spec import layout_positions

    if args.positions is not None:
        if len(args.positions) != args.robots:
            raise UsageError(f"--positions has {len(args.positions)} positions "
                             f"for --robots {args.robots}")  # fmt: skip
        return args.positions
    return layout_positions(args.layout or "chain", args.robots, args.spacing, args.seed)


def _net_up(args) -> int:
    from topology.network import Network
    from topology.spec import NetworkSpec

    if args.positions is not None and args.layout is not None:
        raise UsageError("give either --layout or --positions, not both")
    los = args.range_model in LOS_MODELS
    if los and not args.map:
        raise UsageError(f"--range-model {args.range_model} needs --map PNG (the walls)")
    if args.map and not los:
        raise UsageError("--map is for the los range models: add --range-model los")
    if args.wall_loss_pct is not None and not los:
        raise UsageError("--wall-loss is for the los range models: add --range-model los")
    trace, positions = netextra.up_positions(args)
    try:
        if positions is None:  # not from a --mobility trace
            positions = _start_positions(args)
        spec = NetworkSpec(
            name=args.name,
            positions=tuple(positions),
            map_png=os.path.abspath(args.map) if args.map else None,
            capture_dir=os.path.abspath(args.capture) if args.capture else None,
            **network_fields(args),
        )
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if args.view:
        from testbed.view.server import parse_bind

        try:
            parse_bind(args.view)
        except ValueError as exc:
            raise UsageError(str(exc)) from None
    net = Network(spec, persistent=True)
    net.up()
    links = net.links()
    try:  # what runs beside the network: if any of it fails, nothing is left up
        if args.view:
            _start_net_view(net, args.view)
        netextra.after_up(net, args, trace)
    except BaseException:
        net.down()
        raise
    net.detach()
    print(f"testbed {spec.name}: {spec.robots} robots, {len(links)} links, routing {spec.routing}")
    print(f"  robot K is 10.0.0.K in namespace tb-{spec.name}-rK; try: "
          f"testbed net exec {spec.name} r1 -- ping 10.0.0.{min(2, spec.robots)}")  # fmt: skip
    return 0


def _attach(name: str):
    from topology.network import Network, preflight

    _require_root()
    net = Network.attach(name)
    preflight(net.spec)
    return net


def _require_root() -> None:
    if os.geteuid() != 0:
        raise UsageError("network namespaces need root: run this under sudo")


def _net_exec(args) -> int:
    from topology import names, netns, state

    _require_root()
    cmd = args.command[1:] if args.command[:1] == ["--"] else args.command
    if not cmd:
        raise UsageError("net exec: no command given (testbed net exec NAME rK -- CMD ...)")
    st = state.read(args.name)
    if st is None:
        raise UsageError(f"no testbed named {args.name!r} is up")
    robots = len(st.spec["positions"])
    if args.robot > robots:
        raise UsageError(f"testbed {args.name} has robots r1..r{robots}, not r{args.robot}")
    ns = names.robot_ns(args.name, args.robot)
    if not netns.exists(ns):
        raise UsageError(f"namespace {ns} is gone; try `testbed clean`")
    sys.stdout.flush()
    try:
        os.execvp("ip", netns.popen_argv(ns, cmd))
    except OSError as exc:
        raise UsageError(f"cannot run ip netns exec: {exc.strerror}") from None
    return 1  # not reached


def _net_move(args) -> int:
    from topology import state

    with state.locked(args.name):
        pass  # wait for any change in progress before attaching
    net = _attach(args.name)
    try:
        added, removed = net.move(args.robot, (args.x, args.y))
    finally:
        net.detach()
    for i, j in added:
        print(f"+ {i} {j}")
    for i, j in removed:
        print(f"- {i} {j}")
    return 0


def _net_impair(args) -> int:
    from topology.spec import Impairment

    try:
        imp = Impairment(loss_pct=args.loss, delay_ms=args.delay, jitter_ms=args.jitter,
                         rate_kbit=args.rate)  # fmt: skip
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    net = _attach(args.name)
    try:
        net.impair(args.robot_a, args.robot_b, imp)
    finally:
        net.detach()
    return 0


def _net_links(args) -> int:
    net = _attach(args.name)
    try:
        links = net.medium.kernel_links()
    finally:
        net.detach()
    for i, j in sorted(links):
        print(i, j)
    return 0


def _net_down(args) -> int:
    from topology import names, netns, state
    from topology.network import destroy

    _require_root()
    if state.read(args.name) is None and not netns.exists(names.medium_ns(args.name)):
        raise UsageError(f"no testbed named {args.name!r} is up")
    with state.locked(args.name):
        destroy(args.name)
    print(f"testbed {args.name} is down")
    return 0


def _net_list(args) -> int:
    from topology import state

    for name in state.names():
        st = state.read(name)
        if st is None:
            continue
        kind = "persistent" if st.persistent else f"owned by pid {st.owner_pid}"
        status = "abandoned" if st.abandoned() else "up"
        robots = len(st.spec["positions"])
        print(f"{name}\t{robots} robots\trouting {st.spec['routing']}\t{kind}\t{status}")
    return 0


NET_COMMANDS = {
    "up": _net_up,
    "exec": _net_exec,
    "move": _net_move,
    "impair": _net_impair,
    "links": _net_links,
    "down": _net_down,
    "list": _net_list,
}


# -- clean -------------------------------------------------------------------------------------


def _clean(args) -> int:
    from topology.cleanup import clean

    _require_root()
    removed = clean(everything=args.all)
    if removed:
        print("removed: " + " ".join(removed))
    else:
        print("nothing to clean")
    return 0


# -- run, sweep, report: provided by their own modules -----------------------------------------

DELEGATED = {
    "run": ("testbed.run", "run one exploration experiment"),
    "sweep": ("testbed.sweep", "run a sweep of experiments from a TOML file"),
    "report": ("testbed.analysis.report", "figures and a report from a sweep's results"),
    "view": ("testbed.view.server", "replay a finished run in the browser"),
    "compare": (
        "testbed.analysis.scalecompare",
        "two sweeps of the same points side by side "
        "(e.g. time scale 1 against a dilated one): within the noise or not",
    ),
}


def build_parser(argv: list[str] | None = None) -> Parser:
    """The whole command line. Of the delegated commands only the one named in `argv` (all of
    them when argv names none) has its module imported: `testbed run` starts in a quarter of
    a second instead of paying for the report's matplotlib, and `net` or `clean` import none."""
    parser = Parser(prog="testbed", description=__doc__.splitlines()[0])
    parser.add_argument("-v", "--verbose", action="store_true", help="log what is done")
    sub = parser.add_subparsers(dest="cmd", required=True, parser_class=Parser)
    _add_net(sub)
    cl = sub.add_parser("clean", help="remove what dead or abandoned testbeds left behind")
    cl.add_argument("--all", action="store_true", help="also remove testbeds that are up")
    words = sys.argv[1:] if argv is None else argv
    command = next((w for w in words if not w.startswith("-")), None)
    # `net` and `clean` import none: matplotlib's first import may log a line of its own.
    named = set(words) & set(DELEGATED) or set(DELEGATED)
    chosen = set() if command in ("net", "clean") else named
    for cmd, (module, help_text) in DELEGATED.items():
        p = sub.add_parser(cmd, help=help_text)
        if cmd in chosen and importlib.util.find_spec(module) is not None:
            importlib.import_module(module).add_arguments(p)
    return parser


def dispatch(args) -> int:
    if getattr(args, "handler", None) is not None:  # testbed.netextra's commands
        return args.handler(args)
    if args.cmd == "net":
        return NET_COMMANDS[args.net_cmd](args)
    if args.cmd == "clean":
        return _clean(args)
    return importlib.import_module(DELEGATED[args.cmd][0]).main(args)


# Set once SIGTERM arrived (a batch system cancelling the job, a time limit): whatever the
# run then ended with, it did not end on its own (testbed.slurm marks it interrupted).
terminated = False


def _stop_on_sigterm(signum, frame) -> None:
    global terminated
    terminated = True
    raise KeyboardInterrupt  # unwinds like Ctrl-C: every testbed is torn down on the way out


def main(argv: list[str] | None = None) -> int:
    signal.signal(signal.SIGTERM, _stop_on_sigterm)
    try:
        args = build_parser(argv).parse_args(argv)
        logging.basicConfig(
            level=logging.INFO if args.verbose else logging.WARNING,
            format="%(asctime)s testbed %(name)s %(levelname)s: %(message)s",
        )
        return dispatch(args)
    except TestbedError as exc:
        print(f"testbed: error: {exc}", file=sys.stderr)
        return exc.exit_status
    except KeyboardInterrupt:
        print("testbed: interrupted", file=sys.stderr)
        return 130
    except (OSError, NetlinkError) as exc:  # a kernel or file operation that failed
        print(f"testbed: error: {_os_error_text(exc)}", file=sys.stderr)
        return 1


def _os_error_text(exc: Exception) -> str:
    """`/etc/passwd/x: Not a directory` rather than `[Errno 20] Not a directory: '...'`;
    a NetlinkError (not an OSError) as it prints itself."""
    if isinstance(exc, OSError) and exc.strerror:
        return f"{exc.filename}: {exc.strerror}" if exc.filename else exc.strerror
    return str(exc)


if __name__ == "__main__":
    sys.exit(main())


__all__ = ["main", "EXIT_USAGE"]
