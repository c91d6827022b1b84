"""Replay a file of events against the Python AODV core and print what it did, in the
canonical form the compiled core's driver (build/tb-aodv-core, native/aodv) prints.

Theory of operation
-------------------
There are two AODV protocol cores: aodv/core.py, the reference, and its compiled twin in
native/aodv (docs/aodv.md, "Two cores, held equal"). Both are driven by the same event
file, one JSON object a line:

    {"ev":"init","now":0,"addr":"10.0.0.1","params":{"profile":"rfc",...},
     "rebooted":false,"seq":0,"rreq_id":0}                  a new core (the old one goes)
    {"ev":"control","now":1.5,"src":"10.0.0.2","ttl":1,"bytes":"<hex of the datagram>"}
    {"ev":"no_route","now":..,"src":..,"dst":..,"packet":"<hex>"}
    {"ev":"route_used","now":..,"addr":..}   {"ev":"routes_used","now":..,"addrs":[..]}
    {"ev":"link_lost","now":..,"neighbor":..}
    {"ev":"timer","now":..}    (without "now": at the core's next deadline, or at the last
                                event's time if that is later)
    {"ev":"dump"}              the core's state: routes, neighbours, discoveries, kernel copy

and each prints, per event: for a control event first {"decoded":[...]} (the message as
aodv.packet.decode read it) or {"malformed":true} (decode refused it: the core never sees
it); then one line per action, in the order returned; then {"now":..,"next":..,
"dropped":{..}}, the event's time, `next_deadline()` and the core's `dropped` counters.
Floats are printed with "%.17g", which names every double exactly, so equal text means
equal bits.

    python -m aodv.coretrace EVENTS_FILE                  the Python core's output
    python -m aodv.coretrace --against build/tb-aodv-core EVENTS_FILE
                                                           both, and the first difference
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from collections.abc import Iterable, Iterator
from dataclasses import replace
from typing import Any

from aodv import packet as wire
from aodv.actions import (
    Action,
    Broadcast,
    DeleteRoute,
    DiscoveryDone,
    DropPackets,
    InstallRoute,
    ReleasePackets,
    Unicast,
)
from aodv.core import AodvCore
from aodv.params import Params, profile


def g17(x: float) -> str:
    """A double, exactly (the C driver's "%.17g")."""
    return format(x, ".17g")


def _tf(b: bool) -> str:
    return "true" if b else "false"


def _q(s: str) -> str:
    return json.dumps(s)


def params_of(spec: dict[str, Any] | None) -> Params:
    """Params from an init line's "params": a profile (with its time scale) and overrides."""
    spec = dict(spec or {})
    name = spec.pop("profile", None)
    if name is None:
        return Params(**spec)
    ts = spec.pop("time_scale", 1.0)
    return replace(profile(name, ts), **spec)


def decoded(msg: wire.Message) -> str:
    if isinstance(msg, wire.Rreq):
        fields: list[Any] = [1, msg.rreq_id, msg.dest, msg.dest_seq, msg.orig, msg.orig_seq]
        fields += [msg.hop_count, msg.join, msg.repair, msg.gratuitous, msg.dest_only]
        fields += [msg.unknown_seq]
    elif isinstance(msg, wire.Rrep):
        fields = [2, msg.dest, msg.dest_seq, msg.orig, msg.lifetime_ms, msg.hop_count]
        fields += [msg.repair, msg.ack_required, msg.prefix_size, msg.hello_interval_ms]
    elif isinstance(msg, wire.Rerr):
        fields = [3, [list(u) for u in msg.unreachable], msg.no_delete]
    else:
        fields = [4]
    return json.dumps(fields, separators=(",", ":"))


def _packets(ps: Iterable[bytes]) -> str:
    return "[" + ",".join(f'"{p.hex()}"' for p in ps) + "]"


def action_line(a: Action) -> str:
    if isinstance(a, Unicast):
        return f'{{"a":"unicast","dst":{_q(a.dst)},"ttl":{a.ttl},"msg":"{a.msg.encode().hex()}"}}'
    if isinstance(a, Broadcast):
        return f'{{"a":"broadcast","ttl":{a.ttl},"msg":"{a.msg.encode().hex()}"}}'
    if isinstance(a, InstallRoute):
        return f'{{"a":"install","dest":{_q(a.dest)},"next_hop":{_q(a.next_hop)},"hops":{a.hops}}}'
    if isinstance(a, DeleteRoute):
        return f'{{"a":"delete","dest":{_q(a.dest)}}}'
    if isinstance(a, ReleasePackets):
        return f'{{"a":"release","dest":{_q(a.dest)},"packets":{_packets(a.packets)}}}'
    if isinstance(a, DropPackets):
        return f'{{"a":"drop","dest":{_q(a.dest)},"packets":{_packets(a.packets)}}}'
    if isinstance(a, DiscoveryDone):
        return (
            f'{{"a":"done","dest":{_q(a.dest)},"ok":{_tf(a.ok)},"latency":{g17(a.latency)},'
            f'"round_latency":{g17(a.round_latency)},"repair":{_tf(a.repair)}}}'
        )
    raise TypeError(f"not an action: {a!r}")


def dump_line(core: AodvCore) -> str:
    s = core.state
    routes = []
    for r in s.table.peek_all():
        pre = ",".join(_q(p) for p in sorted(r.precursors))
        routes.append(
            f"[{_q(r.dest)},{_q(r.next_hop)},{r.hops},{r.seq},{_tf(r.valid_seq)},"
            f"{g17(r.lifetime)},{_tf(r.valid)},[{pre}],{g17(r.active_until)}]"
        )
    nbrs = []
    for n in s.neighbors._n.values():
        hello = "null" if n.last_hello is None else g17(n.last_hello)
        nbrs.append(f"[{_q(n.addr)},{hello},{g17(n.last_heard)},{g17(n.timeout)}]")
    discs = []
    for d in s.discoveries.values():
        rh = "null" if d.repair_hops is None else str(d.repair_hops)
        discs.append(
            f"[{_q(d.dest)},{d.ttl},{g17(d.started)},{g17(d.deadline)},{g17(d.round_started)},"
            f"{d.retries},{_tf(d.deferred)},{rh}]"
        )
    inst = [f"[{_q(d)},{_q(nh)},{h}]" for d, (nh, h) in core.datapath.installed.items()]
    reboot = "null" if s.reboot_until is None else g17(s.reboot_until)
    return (
        f'{{"seq":{s.seq},"rreq_id":{s.rreq_id},"routes":[{",".join(routes)}],'
        f'"neighbors":[{",".join(nbrs)}],"discoveries":[{",".join(discs)}],'
        f'"installed":[{",".join(inst)}],"reboot_until":{reboot}}}'
    )


def end_line(now: float, core: AodvCore) -> str:
    dropped = ",".join(f'"{k}":{v}' for k, v in sorted(core.dropped.items()))
    return f'{{"now":{g17(now)},"next":{g17(core.next_deadline())},"dropped":{{{dropped}}}}}'


class Trace:
    """The Python core fed one event at a time; `feed` returns the event's output lines."""

    def __init__(self) -> None:
        self.core: AodvCore | None = None
        self.last_now = 0.0

    def feed(self, ev: dict[str, Any]) -> list[str]:
        kind = ev["ev"]
        if kind == "init":
            now = float(ev["now"])
            self.core = AodvCore(
                ev["addr"],
                params_of(ev.get("params")),
                now,
                bool(ev.get("rebooted", False)),
                int(ev.get("seq", 0)),
                int(ev.get("rreq_id", 0)),
            )
            self.last_now = now
            return [end_line(now, self.core)]
        core = self.core
        if core is None:
            raise ValueError("no init line yet")
        if kind == "dump":
            return [dump_line(core), end_line(self.last_now, core)]
        if kind == "timer" and ev.get("now") is None:
            dl = core.next_deadline()
            now = dl if dl > self.last_now else self.last_now
        else:
            now = float(ev["now"])
        out: list[str] = []
        acts: list[Action] = []
        if kind == "control":
            try:
                msg = wire.decode(bytes.fromhex(ev["bytes"]))
            except wire.MalformedPacket:
                out.append('{"malformed":true}')
            else:
                out.append(f'{{"decoded":{decoded(msg)}}}')
                acts = core.on_control(now, ev["src"], int(ev["ttl"]), msg)
        elif kind == "no_route":
            acts = core.on_no_route(now, ev["src"], ev["dst"], bytes.fromhex(ev["packet"]))
        elif kind == "route_used":
            acts = core.on_route_used(now, ev["addr"])
        elif kind == "routes_used":
            acts = core.on_routes_used(now, list(ev["addrs"]))
        elif kind == "link_lost":
            acts = core.on_link_lost(now, ev["neighbor"])
        elif kind == "timer":
            acts = core.on_timer(now)
        else:
            raise ValueError(f"unknown event {kind!r}")
        out.extend(action_line(a) for a in acts)
        self.last_now = now
        out.append(end_line(now, core))
        return out


def run(lines: Iterable[str]) -> Iterator[str]:
    """The Python core's output for an event file's lines."""
    t = Trace()
    for line in lines:
        if line.strip():
            yield from t.feed(json.loads(line))


class Driver:
    """A long-lived tb-aodv-core fed one event at a time (each event's output ends with its
    "now" line, or is one "error" line)."""

    def __init__(self, binary: str) -> None:
        self.proc = subprocess.Popen(
            [binary],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            bufsize=1,
        )

    def feed(self, line: str) -> list[str]:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write(line.rstrip("\n") + "\n")
        self.proc.stdin.flush()
        out = []
        while True:
            got = self.proc.stdout.readline()
            if not got:
                raise RuntimeError(f"tb-aodv-core ended (status {self.proc.poll()}) on: {line}")
            got = got.rstrip("\n")
            out.append(got)
            if got.startswith('{"now":') or got.startswith('{"error":'):
                return out

    def close(self) -> int:
        assert self.proc.stdin is not None
        self.proc.stdin.close()
        return self.proc.wait()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m aodv.coretrace", description=__doc__.split("\n")[0]
    )
    ap.add_argument("events", help="event file (JSON lines); - for stdin")
    ap.add_argument("--against", metavar="BINARY", help="also run tb-aodv-core and compare")
    args = ap.parse_args(argv)
    src = sys.stdin if args.events == "-" else open(args.events)
    with src:
        lines = [ln for ln in src if ln.strip()]
    if args.against is None:
        for out in run(lines):
            print(out)
        return 0
    trace, driver = Trace(), Driver(args.against)
    compared = 0
    try:
        for n, line in enumerate(lines, 1):
            want, got = trace.feed(json.loads(line)), driver.feed(line)
            for k in range(max(len(want), len(got))):
                w = want[k] if k < len(want) else "(nothing)"
                g = got[k] if k < len(got) else "(nothing)"
                if w != g:
                    print(f"event {n}: {line.strip()}\n  python: {w}\n  c++:    {g}")
                    return 1
            compared += len(want)
    finally:
        driver.close()
    print(f"{len(lines)} events, {compared} output lines: the two cores agree")
    return 0


if __name__ == "__main__":
    sys.exit(main())
