"""Command-line pieces for bringing your own robots: `net up --mobility FILE` (a trace
player), `net up --feed` and `net feed NAME` (a live position feed). testbed.cli calls
add_up_arguments, add_parsers, up_positions, check_up and after_up; everything else is here.

Where a trace's link timeline goes: `--links-out CSV`, else links.csv in `--capture DIR`,
else NAME-links.csv in the directory `net up` runs in. Never in the testbed's run dir, which
`net down` deletes; a default that would overwrite an earlier timeline is refused.
"""

import argparse
import math
import os
import socket
import subprocess
import sys
import time

from common.argtypes import number
from common.errors import TestbedError, UsageError
from topology.inputs.mobility import LIMITS_TEXT, MIN_TICK_S

READY_TIMEOUT_S = 10.0


def add_up_arguments(up) -> None:
    """The options of `net up` that belong here."""
    up.add_argument("--mobility", metavar="FILE",
                    help="play an ns-2 movement file (BonnMotion NSFile, CORE) or a ONE trace; "
                         "the file's nodes in ascending order of id are robots r1, r2, ... "
                         "(node i is robot i+1 when ids start at 0), --robots defaults to the "
                         f"file's nodes; limits: {LIMITS_TEXT}")  # fmt: skip
    up.add_argument("--tick", type=number(float, "tick", minimum=MIN_TICK_S), default=0.1,
                    metavar="S", help=f"with --mobility: emulated s between samples, at least "
                    f"{MIN_TICK_S:g} (default 0.1)")  # fmt: skip
    up.add_argument("--links-out", metavar="CSV",
                    help="with --mobility: where the applied link timeline goes (default: "
                         "links.csv in the --capture dir, else NAME-links.csv here; kept after "
                         "net down, never overwritten by default)")  # fmt: skip
    up.add_argument("--feed", action="store_true",
                    help="open the position feed socket (see `testbed net feed`)")  # fmt: skip


def add_parsers(nsub, sub, name_type) -> None:
    """`net feed` (and its siblings to come) under `net`; top-level commands under `sub`."""
    from topology.inputs import feed
    from topology.spec import MAX_COORD_M

    fd = nsub.add_parser(
        "feed",
        help="move robots from lines 'ID X Y' or 'T ID X Y' on stdin",
        description="Move robots from lines 'ID X Y' (at once) or 'T ID X Y' (at emulated "
        "time T s after the feed started) on standard input. Limits: a line is at most "
        f"{feed.MAX_LINE_BYTES} bytes; |X|, |Y| <= {MAX_COORD_M:,.0f} m; "
        f"0 <= T <= {feed.MAX_TIME_S:,.0f} s; at most {feed.MAX_PENDING} timed updates wait at "
        "once. A last line without a newline is that line; a bad line ends the feed "
        "(exit 2).",
    )
    fd.add_argument("name", type=name_type)
    fd.add_argument("--no-stdin", action="store_true", help=argparse.SUPPRESS)
    fd.set_defaults(handler=net_feed)
    mt = sub.add_parser("metrics", help="PDF, delay and control overhead from the captures "
                        "of a `net up --capture DIR` network")  # fmt: skip
    mt.add_argument("dir", metavar="DIR")
    mt.set_defaults(handler=metrics)


def up_positions(args):
    """(trace, positions) for `net up`: the trace's positions at time 0 with --mobility,
    else (None, None). Sets args.robots from the trace when it was not given."""
    if not args.mobility:
        if args.robots is None:
            raise UsageError("net up: --robots is required (unless --mobility gives it)")
        return None, None
    from topology.inputs import mobility

    if args.positions is not None or args.layout is not None:
        raise UsageError("--mobility gives the positions: drop --layout/--positions")
    try:
        trace = mobility.load(args.mobility)
    except mobility.TraceError as exc:
        raise UsageError(str(exc)) from None
    if args.robots is None:
        args.robots = trace.nodes
    elif args.robots > trace.nodes:
        raise UsageError(f"--robots {args.robots}, but {args.mobility} has {trace.nodes} nodes")
    return trace, trace.positions(0.0, args.robots)


def links_out(args) -> str | None:
    """Where the trace player writes its link timeline (None without --mobility); a
    UsageError if a default place already holds one or cannot be written."""
    if not args.mobility:
        return None
    if args.links_out:
        out = os.path.abspath(args.links_out)
    else:
        where = args.capture or os.getcwd()
        out = os.path.abspath(os.path.join(where, "links.csv" if args.capture else
                                           f"{args.name}-links.csv"))  # fmt: skip
        if os.path.lexists(out):
            raise UsageError(f"{out} holds an earlier link timeline: move it, or give "
                             "--links-out CSV")  # fmt: skip
    parent = os.path.dirname(out)
    if args.capture and parent == os.path.abspath(args.capture):
        return out  # net up makes the capture dir (and check_writable_dir checked it)
    check_writable_dir(parent, f"--links-out {out}")
    return out


def check_writable_dir(path: str, what: str) -> None:
    """UsageError unless a file can be made in directory `path` (or in the directory that
    would hold it, where it does not exist yet): tried, as os.access is always yes for
    root, even on /proc."""
    import tempfile

    probe = path
    while not os.path.isdir(probe):
        parent = os.path.dirname(probe)
        if parent == probe or os.path.lexists(probe):
            raise UsageError(f"{what}: {path} is not a directory")
        probe = parent
    try:
        with tempfile.TemporaryFile(dir=probe):
            pass
    except OSError as e:
        raise UsageError(f"{what}: cannot write in {probe} ({e.strerror or e})") from None


def check_up(args, trace) -> dict:
    """What after_up needs, checked before the network is made (UsageError if not)."""
    return {"links_out": links_out(args) if trace is not None else None}


def after_up(net, args, trace, extras: dict) -> list[str]:
    """Start what runs beside the network: the trace player, the feed server. Returns the
    lines that tell the user where their output and input go."""
    lines = []
    if trace is not None:
        out = extras["links_out"]
        ready = os.path.join(net.state_dir, "mobility.ready")
        argv = [sys.executable, "-m", "topology.inputs.player", net.name,
                os.path.abspath(args.mobility), "--tick", repr(args.tick),
                "--links-out", out, "--ready", ready]  # fmt: skip
        proc = _start(net, argv, "mobility")
        _wait_ready(proc, ready, os.path.join(net.state_dir, "mobility.log"), "the trace player")
        robots = net.spec.robots
        if net.spec.capture_dir:
            _record_mapping(net.spec.capture_dir, os.path.abspath(args.mobility), trace, robots)
        lines.append(f"trace: {trace.nodes} nodes, {trace.end:g} s emulated; links to {out} "
                     "(kept after net down)")  # fmt: skip
        lines.append(f"trace {trace.mapping_text(robots)}")
    if args.feed:
        from topology.inputs import feed

        argv = [sys.executable, "-m", "testbed.cli", "net", "feed", net.name, "--no-stdin"]
        proc = _start(net, argv, "feed")
        path = feed.socket_path(net.name)
        deadline = time.monotonic() + READY_TIMEOUT_S
        while not os.path.exists(path):
            if proc.poll() is not None or time.monotonic() > deadline:
                with open(os.path.join(net.state_dir, "feed.log"), errors="replace") as f:
                    last = (f.read().strip().splitlines() or ["(no output)"])[-1]
                raise TestbedError(f"the feed server did not start: {last}")
            time.sleep(0.02)
        lines.append(f"feed: {path}")
    return lines


def _record_mapping(capture_dir: str, path: str, trace, robots: int) -> None:
    """Add to the capture's network.json which trace file was played and which of its nodes
    is which robot: {"mobility": {"file": path, "robot_of_node": {"6": 1, ...}}}."""
    from common.jsonfile import read_json, write_json_atomic

    about_path = os.path.join(capture_dir, "daemons", "network.json")
    about = read_json(about_path)
    if not isinstance(about, dict):  # net up wrote it: only a hand that removed it gets here
        return
    about["mobility"] = {
        "file": path,
        "robot_of_node": {str(node): k for node, k in trace.robot_of_node(robots).items()},
    }
    write_json_atomic(about_path, about)


def _wait_ready(proc, ready: str, log_path: str, what: str) -> None:
    """Until `ready` exists; TestbedError with the last line of the process's log when it
    exits first or does not get there in READY_TIMEOUT_S."""
    deadline = time.monotonic() + READY_TIMEOUT_S
    while not os.path.exists(ready):
        if proc.poll() is not None or time.monotonic() > deadline:
            last = _last_line(log_path)
            how = f"exited with status {proc.returncode}" if proc.poll() is not None else (
                f"did not start in {READY_TIMEOUT_S:g} s")  # fmt: skip
            raise TestbedError(f"{what} {how}" + (f": {last}" if last else ""))
        time.sleep(0.02)


def _last_line(path: str) -> str:
    """The last line of a log, without its time stamp and process name."""
    try:
        with open(path, errors="replace") as f:
            lines = [ln.strip() for ln in f if ln.strip()]
    except OSError:
        return ""
    last = lines[-1] if lines else ""
    return last.split(" player ", 1)[-1].removeprefix("error: ")[:200]


def _start(net, argv: list[str], role: str):
    log = open(os.path.join(net.state_dir, f"{role}.log"), "w")  # noqa: SIM115 (the child's)
    proc = subprocess.Popen(argv, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                            start_new_session=True)  # fmt: skip
    net.adopt_host_process(proc, role)
    return proc


def net_feed(args) -> int:
    """Client of a running feed server if there is one, else the server itself."""
    from topology import state
    from topology.inputs import feed

    if os.geteuid() != 0:
        raise UsageError("network namespaces need root: run this under sudo")
    if state.read(args.name) is None:
        raise UsageError(f"no testbed named {args.name!r} is up")
    path = feed.socket_path(args.name)
    if not args.no_stdin and os.path.exists(path):
        try:
            return _feed_client(path)
        except ConnectionRefusedError:
            pass  # a stale socket: serve ourselves
    from topology.network import Network

    net = Network.attach(args.name)
    server = feed.FeedServer(net, path, stdin=not args.no_stdin)
    try:
        server.serve(until_stdin_closes=not args.no_stdin)
    except feed.FeedError as exc:
        raise UsageError(f"net feed: stdin {exc}") from None
    finally:
        server.close()
        net.detach()
    return 0


def _feed_client(path: str) -> int:
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.connect(path)
        while chunk := os.read(0, 1 << 16):
            s.sendall(chunk)
        s.shutdown(socket.SHUT_WR)
        first = bytearray()  # the server's first answer line: the first bad line's error
        while data := s.recv(1 << 16):
            if len(first) < 1024:
                first += data[: 1024 - len(first)]
    errors = first.decode(errors="replace").strip()
    if errors:
        print(f"testbed: net feed: {errors.splitlines()[0]}", file=sys.stderr)
        return 2
    return 0


def network_of(path: str) -> tuple[str, float | None]:
    """(routing, time scale) of a capture directory's daemons/network.json (`net up`
    wrote it; its type is testbed.files.networkfile): ("aodv", None) where it is missing;
    UsageError, one line naming the file and the key, where it is there but not one (a FIFO
    is refused, not waited on)."""
    from testbed.files import networkfile

    try:
        net = networkfile.read(path) or networkfile.NetworkRecord()
    except networkfile.ResultError as e:
        raise UsageError(f"metrics: {e}") from None
    return net.routing, net.time_scale


def _finite(value):
    """`value` with every number that is not finite as None (metrics.json is strict JSON)."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value


def metrics(args) -> int:
    """`testbed metrics DIR`: testbed.analysis.pcapmetrics.run_metrics on the captures of a
    `net up --capture DIR` network (laid out as a run's pcaps/), written to DIR/metrics.json."""
    import re
    import tempfile

    from common.jsonfile import write_json_atomic
    from testbed.analysis import pcapmetrics

    d = os.path.abspath(args.dir)
    if not os.path.isdir(d):
        raise UsageError(f"metrics: {args.dir} is not a directory")
    if not any(re.fullmatch(r"r\d+\.pcap", e) for e in os.listdir(d)):
        raise UsageError(f"metrics: {args.dir} has no rK.pcap (made by `net up --capture DIR`)")
    from testbed.files.networkfile import network_path

    routing, scale = network_of(network_path(d))
    with tempfile.TemporaryDirectory(prefix="tb-metrics-") as tmp:
        os.symlink(d, os.path.join(tmp, "pcaps"))  # laid out as a run's directory
        m = pcapmetrics.run_metrics(tmp, use_cache=False, network=(routing, scale))
    if m is None:
        raise UsageError(f"metrics: no captures in {args.dir}")
    doc = {k: v for k, v in m.to_json().items() if k not in ("pcaps",)}
    out = os.path.join(d, "metrics.json")  # routing.json's type (testbed.files.routingfile)
    write_json_atomic(out, _finite(doc), strict=True)  # never through a link; no NaN or Infinity

    def fmt(v, spec: str) -> str:
        return "n/a" if v is None else format(v, spec)

    print(
        f"routing {routing}: {len(doc.get('robots') or {})} captures, {fmt(m.duration_s, '.1f')} s"
    )
    print(f"  PDF (TCP payload bytes delivered): {fmt(m.pdf, '.4f')}")
    print(
        f"  delay ms: median {fmt(m.delay_ms_median, '.2f')}, "
        f"mean {fmt(m.delay_ms_mean, '.2f')}, p95 {fmt(m.delay_ms_p95, '.2f')}"
    )
    print(
        f"  control overhead: {m.control_tx_packets} packets, "
        f"{fmt(m.overhead_packets, '.4f')} of frames, {fmt(m.overhead_bytes, '.4f')} of bytes"
    )
    if m.captures_left_out:
        from testbed.analysis.runreport import left_out_text

        print(f"  captures left out (not counted): {left_out_text(m.captures_left_out)}")
    print(f"  written to {out}")
    return 0
