"""`testbed net ...` and `testbed clean`: networks made, used and taken down by hand.

`add_parsers` adds the `net` and `clean` subcommands to the `testbed` command line (its
parser class, a UsageError on bad input, is the one testbed.cli gives) and `run` carries
one of them out. The trace player's and the live feed's own options and subcommands are
testbed.net.movers'. The network options are `testbed run`'s own (testbed.files.runconfig).
"""

import argparse
import logging
import os
import sys

from common.argtypes import checked, number
from common.errors import UsageError
from testbed.files import options as runoptions
from testbed.files.runconfig import NET_OPTIONS
from testbed.net import movers
from testbed.run import daemonchoice
from testbed.run.arguments import network_fields
from topology.names import check_name, parse_robot_ref
from topology.spec import LAYOUTS, LOS_MODELS, MAX_COORD_M

log = logging.getLogger("testbed")


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


_robot_ref = checked(parse_robot_ref)


def _positions(text: str) -> list[tuple[float, float]]:
    from topology.spec import check_position

    out = []
    for item in text.replace(";", " ").split():
        try:
            out.append(check_position(item.split(","), f"position {item[:40]!r}"))
        except ValueError as exc:
            if "," not in item or item.count(",") > 1:
                raise argparse.ArgumentTypeError(f"position {item[:40]!r} is not X,Y") from None
            raise argparse.ArgumentTypeError(str(exc)) from None
    if not out:
        raise argparse.ArgumentTypeError("--positions is empty")
    return out


_name = checked(check_name)


# -- net ---------------------------------------------------------------------------------------


NAME_HELP = "the testbed's name (as given to net up)"
ROBOT_HELP = "a robot, rK (K from 1)"


def add_parsers(sub) -> None:
    """`net` with its subcommands, and `clean`, on the `testbed` command's subparsers."""
    net = sub.add_parser("net", help="bring a network up by hand, use it, take it down")
    nsub = net.add_subparsers(dest="net_cmd", required=True, parser_class=type(net))

    up = nsub.add_parser("up", help="build a testbed network and leave it running")
    up.add_argument("name", type=_name, help="the testbed's name (lowercase letters, digits)")
    up.add_argument("--robots", type=_robot_count, metavar="N",
                    help="robots (required, unless --mobility's file gives them)")  # fmt: skip
    up.add_argument("--layout", choices=LAYOUTS, help="where the robots stand (default chain)")
    up.add_argument("--spacing", type=number(float, "spacing", above=0), default=8.0, metavar="M",
                    help="distance between neighbours of --layout (metres; default 8)")  # fmt: skip
    up.add_argument("--positions", type=_positions, metavar='"X,Y X,Y ..."',
                    help="where the robots stand (metres, each within 10,000,000 of 0; "
                         "instead of --layout)")  # fmt: skip
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
        help="serve a live view of the network (127.0.0.1 unless a host is given; default "
        "none; a port in use is refused before anything is made)",
    )
    movers.add_up_arguments(up)
    movers.add_parsers(nsub, sub, _name)

    ex = nsub.add_parser("exec", help="run a command in a robot's namespace")
    ex.add_argument("name", type=_name, help=NAME_HELP)
    ex.add_argument("robot", type=_robot_ref, help=ROBOT_HELP)
    ex.add_argument("command", nargs=argparse.REMAINDER, help="-- CMD ARG ...: what to run")

    mv = nsub.add_parser("move", help="move a robot; links follow before this returns")
    mv.add_argument("name", type=_name, help=NAME_HELP)
    mv.add_argument("robot", type=_robot_ref, help=ROBOT_HELP)
    mv.add_argument("x", type=number(float, "x", magnitude=MAX_COORD_M), help="new x (metres)")
    mv.add_argument("y", type=number(float, "y", magnitude=MAX_COORD_M), help="new y (metres)")

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

    cl = sub.add_parser("clean", help="remove what dead or abandoned testbeds left behind")
    cl.add_argument("--all", action="store_true", help="also remove testbeds that are up")


VIEW_READY_TIMEOUT_S = 10.0


def _start_net_view(net, bind: str) -> str:
    """The view of a `net up` network: a process of its own (testbed.view.netview), recorded
    with the testbed so that `net down` stops it. Returns its address once it listens;
    UsageError (its own line) if it does not."""
    import subprocess
    import time

    from testbed.view.netview import ready_path

    logp = os.path.join(net.state_dir, "view.log")
    with open(logp, "w") as log:
        proc = subprocess.Popen(
            [sys.executable, "-m", "testbed.view.netview", net.name, bind],
            stdout=log, stderr=subprocess.STDOUT, start_new_session=True,
        )  # fmt: skip
    net.adopt_host_process(proc, "view")
    deadline = time.monotonic() + VIEW_READY_TIMEOUT_S
    while not os.path.exists(ready_path(net.name)):
        if proc.poll() is not None or time.monotonic() > deadline:
            with open(logp, errors="replace") as f:
                last = (f.read().strip().splitlines() or ["(no output)"])[-1]
            raise UsageError(f"the live view did not start: {last.removeprefix('netview: ')}")
        time.sleep(0.02)
    return f"http://{bind if ':' in bind else '127.0.0.1:' + bind}/"


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
    if args.capture:
        movers.check_writable_dir(os.path.abspath(args.capture), f"--capture {args.capture}")
    trace, positions = movers.up_positions(args)
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
        _, daemon_reason = daemonchoice.choose(args.aodv_daemon, args.routing)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if args.view:
        from testbed.view.server import check_bind

        try:
            check_bind(args.view)  # a busy port is refused before anything is made
        except ValueError as exc:
            raise UsageError(str(exc)) from None
    extras = movers.check_up(args, trace)
    net = Network(spec, persistent=True)
    net.up()
    try:  # what runs beside the network: all of it starts, or the network goes down again
        links = net.links()
        view = _start_net_view(net, args.view) if args.view else None
        started = movers.after_up(net, args, trace, extras)
    except BaseException:
        net.down()
        raise
    net.detach()
    print(f"testbed {spec.name}: {spec.robots} robots, {len(links)} links, routing {spec.routing}")
    if spec.routing == "aodv":  # which AODV daemon runs, and why (testbed.run.daemonchoice)
        print(f"  AODV daemon: {spec.aodv_daemon} ({daemon_reason})")
    print(f"  robot K is 10.0.0.K in namespace tb-{spec.name}-rK; try: "
          f"testbed net exec {spec.name} r1 -- ping 10.0.0.{min(2, spec.robots)}")  # fmt: skip
    if spec.time_scale != 1 and net.timers is not None:
        print(f"  {net.timers.summary()}")
    if view:
        print(f"  live view: {view}")
    for line in started:
        print(f"  {line}")
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
    from topology import names, state
    from topology.kernel import netns

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

    _require_root()
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
    from topology import names, state
    from topology.kernel import netns
    from topology.network import destroy

    _require_root()
    if not state.exists(args.name) and not netns.exists(names.medium_ns(args.name)):
        raise UsageError(f"no testbed named {args.name!r} is up")
    with state.locked(args.name):
        destroy(args.name)
    print(f"testbed {args.name} is down")
    return 0


def _net_list(args) -> int:
    from topology import state

    for name in state.names():
        try:
            st = state.read(name)
        except state.UntrustedState as exc:
            print(f"testbed: warning: {exc}", file=sys.stderr)
            continue
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


def run(args) -> int:
    """Carry out the `net` or `clean` command that `args` holds."""
    if getattr(args, "handler", None) is not None:  # testbed.net.movers' commands
        return args.handler(args)
    if args.cmd == "clean":
        return _clean(args)
    return NET_COMMANDS[args.net_cmd](args)
