"""One protocol, two cores, held equal: the Python AODV core (aodv/core.py, the reference) and
its compiled twin (native/aodv, driven by build/tb-aodv-core) take the same event sequences
and must print the same lines: the decoded message (or the same MalformedPacket decision),
the same actions in the same order, the same next deadline and `dropped` counters after
every event, bit for bit (aodv/coretrace.py has the canonical form).

The sequences come from three sources. (1) Recorded: small random topologies run in the
in-memory medium (aodv/sim.py: real discoveries, RREPs, HELLOs, RERRs, repairs, RREP-ACKs
over one-way links), each node's events taken as they reached its core, then mutated
(bytes flipped, truncated or given extensions, IP TTLs changed, events dropped, repeated or
inserted, the node restarted as rebooted). (2) Random: one node fed messages drawn from a
handful of addresses with extreme fields (hop counts 0/34/35/255, sequence numbers at the
32-bit wrap, lifetimes and Hello Intervals of 0 and 2**32-1, unknown and reserved
extensions, raw garbage), floods of forged originators past the table and cache bounds,
data without a route, route use, lost links and timers at the core's own deadlines.
(3) Fixed scenarios: a chain discovery, a link break with its RERR, a HELLO loss, the
reboot rule. A failing sequence is written to build/aodv-differential-failure.jsonl:
`python -m aodv.coretrace --against build/tb-aodv-core <file>` replays it.

The same corpus runs through the AddressSanitizer/UndefinedBehaviorSanitizer build
(build/asan/tb-aodv-core) in test_sanitized_core_agrees (marked slow)."""

from __future__ import annotations

import functools
import json
import random
import shutil
import subprocess
from collections import Counter
from dataclasses import fields
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from aodv import packet as wire
from aodv.coretrace import Driver, Trace, params_of
from aodv.params import Params
from aodv.sim import Medium

REPO = Path(__file__).resolve().parents[2]
BINARY = REPO / "build" / "tb-aodv-core"
UNBUILT = REPO / "build" / "tb-aodv-core.unbuilt"
ASAN_BINARY = REPO / "build" / "asan" / "tb-aodv-core"
FAILURE = REPO / "build" / "aodv-differential-failure.jsonl"

POOL = [f"10.0.0.{k}" for k in range(1, 7)]
STATS: Counter[str] = Counter()  # sequences, events, lines compared (reported at the end)

Event = dict[str, Any]


def _build(target: Path) -> str | None:
    """Bring a build up to date where g++ is here; the reason to skip where it cannot be."""
    if shutil.which("g++") is not None and shutil.which("make") is not None:
        done = subprocess.run(["make", "-s", str(target.relative_to(REPO))], cwd=REPO,
                              capture_output=True, text=True, timeout=600)  # fmt: skip
        if done.returncode != 0 and not target.exists():
            return f"{target.name} not built: make failed: {done.stdout}{done.stderr}"
    if not target.exists():
        if UNBUILT.exists() and target == BINARY:
            return UNBUILT.read_text().strip()
        return f"{target.relative_to(REPO)} not built (needs g++: run make setup)"
    return None


class Drivers:
    """One long-lived driver process per binary, restarted if an example killed it."""

    def __init__(self, binary: Path) -> None:
        self.binary = binary
        self.driver: Driver | None = None

    def get(self) -> Driver:
        if self.driver is None or self.driver.proc.poll() is not None:
            self.driver = Driver(str(self.binary))
        return self.driver

    def close(self) -> None:
        if self.driver is not None and self.driver.proc.poll() is None:
            self.driver.close()


@pytest.fixture(scope="module")
def core_binary():
    reason = _build(BINARY)
    if reason is not None:
        pytest.skip(reason)
    d = Drivers(BINARY)
    yield d
    d.close()


def compare(drivers: Drivers, events: list[Event]) -> int:
    """Feed one sequence to both cores; assert equal output; return the lines compared."""
    trace, driver = Trace(), drivers.get()
    lines = [json.dumps(ev, separators=(",", ":")) for ev in events]
    compared = actions = 0
    for n, line in enumerate(lines):
        want = trace.feed(json.loads(line))
        try:
            got = driver.feed(line)
        except RuntimeError:
            got = ["(the driver died)"]
        if got != want:
            FAILURE.parent.mkdir(exist_ok=True)
            FAILURE.write_text("\n".join(lines[: n + 1]) + "\n")
            pad = max(len(want), len(got))
            w_all, g_all = want + [""] * pad, got + [""] * pad
            k = next(k for k in range(pad) if w_all[k] != g_all[k])
            diff = (k, w_all[k], g_all[k])
            raise AssertionError(
                f"event {n + 1} of {len(lines)}: {line}\n line {diff[0]}\n  python: {diff[1]}"
                f"\n  c++:    {diff[2]}\n(replay: python -m aodv.coretrace --against "
                f"{drivers.binary.relative_to(REPO)} {FAILURE.relative_to(REPO)})"
            )
        compared += len(want)
        actions += sum(1 for w in want if w.startswith('{"a":'))
    STATS["sequences"] += 1
    STATS["events"] += len(lines)
    STATS["lines"] += compared
    STATS["actions"] += actions
    return compared


# == parameters ============================================================================
PARAM_CHOICES: dict[str, list[Any]] = {
    "queue_len": [1, 2, 64],
    "rreq_ratelimit": [1, 2, 10],
    "rerr_ratelimit": [1, 10],
    "rreq_forward_ratelimit": [1, 3, 100],
    "route_table_limit": [16, 1024],
    "neighbor_limit": [16, 256],
    "rreq_cache_limit": [16, 4096],
    "local_repair": [True, False],
    "gratuitous_rrep": [True, False],
    "dest_only": [False, True],
    "hello_interval_ms": [250, 1000, 1500.5],
    "active_route_timeout_ms": [500, 3000, 2999.9],
    "node_traversal_time_ms": [10, 40, 40.5],
    "net_diameter": [10, 35, 255],
    "ttl_start": [1, 2, 5],
    "ttl_threshold": [7, 9],
    "ttl_increment": [1, 2, 3],
    "allowed_hello_loss": [1, 2, 5],
    "rreq_retries": [0, 2, 4],
    "timeout_buffer": [0, 2],
    "delete_period_k": [1, 5],
    "my_route_timeout_ms": [None, 60000],
    "blacklist_timeout_ms": [None, 700],
}


# The bounds against floods at their smallest, and rate limits low enough to be reached.
TIGHT_BOUNDS = {
    "route_table_limit": 16,
    "neighbor_limit": 16,
    "rreq_cache_limit": 16,
    "rreq_forward_ratelimit": 3,
    "rerr_ratelimit": 1,
    "rreq_ratelimit": 2,
    "queue_len": 2,
}


@st.composite
def param_specs(draw) -> dict[str, Any]:
    spec: dict[str, Any] = {"profile": draw(st.sampled_from(["rfc", "ns3"]))}
    spec["time_scale"] = draw(st.sampled_from([1.0, 1.0, 10.0, 0.5, 3.0, 7]))
    if draw(st.booleans()):
        spec.update(TIGHT_BOUNDS)
    if draw(st.booleans()):
        for name in draw(st.lists(st.sampled_from(sorted(PARAM_CHOICES)), max_size=6)):
            spec[name] = draw(st.sampled_from(PARAM_CHOICES[name]))
    # Overrides that break a section 10 constraint go, the last first, until none does.
    for name in reversed([k for k in spec if k in PARAM_CHOICES]):
        if not params_of(spec).problems():
            break
        del spec[name]
    return spec


def params_spec(p: Params) -> dict[str, Any]:
    return {f.name: getattr(p, f.name) for f in fields(Params)}


# == random messages =======================================================================
EXTREME_U32 = [0, 1, 2, 0x7FFFFFFF, 0x80000000, 0x80000001, 0xFFFFFFFE, 0xFFFFFFFF]
u32 = st.one_of(st.sampled_from(EXTREME_U32), st.integers(0, 2**32 - 1))
seqs = st.one_of(st.integers(0, 6), st.integers(0, 6), st.sampled_from(EXTREME_U32))
hop_counts = st.one_of(st.integers(0, 4), st.sampled_from([9, 10, 34, 35, 36, 254, 255]))
lifetimes = st.one_of(
    st.sampled_from([0, 1, 499, 500, 3000, 11200, 112000, 112001, 600000, 600001]),
    u32,
)
hello_ms = st.sampled_from([0, 1, 62, 63, 250, 1000, 1500, 16000, 24000, 24001, 2**32 - 1])
far_addr = st.integers(0, 2**32 - 1).map(lambda v: wire._addr(v.to_bytes(4, "big")))
addrs = st.one_of(st.sampled_from(POOL), st.sampled_from(POOL), far_addr)
WIDE = (addrs, seqs, hop_counts)
NARROW = (st.sampled_from(POOL[:4]), st.integers(0, 2), st.integers(0, 2))
EXTENSIONS = [
    b"\x01\x04\x00\x00\x03\xe8",  # Hello Interval 1000
    b"\x02\x04\x00\x00\x01\xf4",  # Wireshark's type 2
    b"\x01\x04\x00\x00\x03\xe8\x02\x04\x00\x00\x00\x01",
    b"\x02\x04\x00\x00\x00\x00\x01\x03abc",  # type 1 of 3 bytes: malformed
    b"\x01\x03abc",
    b"\x02\x05abcde",
    b"\x03\x00",  # unknown, skipped
    b"\x7f\x02ab",
    b"\x80\x00",  # >= 128: may not be skipped
    b"\xff\x01a",
    b"\x00\x00",  # type 0: reserved
    b"\x05",  # truncated header
    b"\x05\x09abc",  # claims more than is left
    b"\x01\x04\xff\xff\xff\xff",
]


@st.composite
def messages(draw, src: str, narrow: bool = False) -> bytes:
    """A datagram from `src`; `narrow` draws from few addresses and small numbers, so that
    messages meet: the same originator, sequence number and hop count by two paths."""
    addrs, seqs, hop_counts = NARROW if narrow else WIDE
    kind = draw(st.sampled_from(["rreq", "rreq", "rrep", "hello", "hello", "rerr", "ack", "raw"]))
    if kind == "rreq":
        rreq_ids = st.integers(0, 3) if narrow else st.one_of(st.integers(0, 5), u32)
        m: wire.Message = wire.Rreq(
            draw(rreq_ids), draw(addrs), draw(seqs), draw(addrs),
            draw(seqs), draw(hop_counts), *draw(st.lists(st.booleans(), min_size=5, max_size=5)),
        )  # fmt: skip
    elif kind == "rrep":
        m = wire.Rrep(
            draw(addrs), draw(seqs), draw(addrs), draw(lifetimes), draw(hop_counts),
            draw(st.booleans()), draw(st.booleans()), draw(st.integers(0, 31)),
            draw(st.one_of(st.none(), hello_ms)),
        )  # fmt: skip
    elif kind == "hello":
        m = wire.Rrep(src, draw(seqs), src, draw(lifetimes), 0,
                      hello_interval_ms=draw(st.one_of(hello_ms, st.none())))  # fmt: skip
    elif kind == "rerr":
        dests = draw(st.lists(st.tuples(addrs, seqs), min_size=1, max_size=4))
        m = wire.Rerr(tuple(dests), draw(st.booleans()))
    elif kind == "ack":
        m = wire.RrepAck()
    else:
        return bytes([draw(st.integers(0, 6))]) + draw(st.binary(max_size=40))
    raw = m.encode()
    how = draw(st.sampled_from(["as is"] * 6 + ["extend", "truncate", "flip", "lengthen"]))
    if how == "extend":
        raw += draw(st.sampled_from(EXTENSIONS))
    elif how == "truncate":
        raw = raw[: draw(st.integers(0, max(0, len(raw) - 1)))]
    elif how == "flip":
        i = draw(st.integers(0, len(raw) - 1))
        raw = raw[:i] + bytes([raw[i] ^ draw(st.integers(1, 255))]) + raw[i + 1 :]
    elif how == "lengthen" and isinstance(m, wire.Rerr):
        raw = raw[:3] + bytes([min(255, raw[3] + 1)]) + raw[4:]
    return raw


@st.composite
def random_sequences(draw) -> list[Event]:
    me = draw(st.sampled_from(POOL))
    now = draw(st.sampled_from([0.0, 0.0, 5.25, 123456.789, 1e6 + 0.1]))
    rebooted = draw(st.booleans())
    init: Event = {
        "ev": "init", "now": now, "addr": me, "params": draw(param_specs()),
        "rebooted": rebooted, "seq": draw(seqs), "rreq_id": draw(seqs),
    }  # fmt: skip
    events = [init]
    others = [a for a in POOL if a != me]
    narrow = draw(st.booleans())
    steps = st.sampled_from([0.0, 0.0, 1e-6, 0.0005, 0.001, 0.04, 0.3, 1.0, 2.5, 7.0, 30.0])
    for _ in range(draw(st.integers(1, 60))):
        kind = draw(st.sampled_from(
            ["control"] * 8 + ["no_route"] * 2 + ["used", "used_many", "lost", "dump", "flood"]
            + ["timer"] * 4 + ["timer_at"]
        ))  # fmt: skip
        if kind == "timer":
            events.append({"ev": "timer"})  # at the core's own deadline
            continue
        now += draw(steps)
        src = draw(st.one_of(st.sampled_from(others), st.just(me), addrs))
        if kind == "control":
            raw = draw(messages(src, narrow))
            ttl = draw(st.sampled_from([0, 1, 1, 2, 3, 64, 255]))
            events.append({"ev": "control", "now": now, "src": src, "ttl": ttl, "bytes": raw.hex()})
        elif kind == "no_route":
            s = draw(st.sampled_from([me, me, src]))
            dst = draw(addrs)
            pkt = draw(st.binary(min_size=1, max_size=6)).hex()
            events.append({"ev": "no_route", "now": now, "src": s, "dst": dst, "packet": pkt})
        elif kind == "used":
            events.append({"ev": "route_used", "now": now, "addr": draw(addrs)})
        elif kind == "used_many":
            many = draw(st.lists(addrs, max_size=4))
            events.append({"ev": "routes_used", "now": now, "addrs": many})
        elif kind == "lost":
            events.append({"ev": "link_lost", "now": now, "neighbor": draw(addrs)})
        elif kind == "dump":
            events.append({"ev": "dump"})
        elif kind == "timer_at":
            events.append({"ev": "timer", "now": now})
        else:  # a flood of RREQs from forged originators (and sources): past every bound
            seed = draw(st.integers(0, 2**32 - 1))
            rng = random.Random(seed)
            for k in range(draw(st.integers(17, 40))):
                orig = f"10.{rng.randrange(1, 255)}.{rng.randrange(256)}.{rng.randrange(1, 255)}"
                fsrc = orig if rng.random() < 0.5 else draw(st.sampled_from(others))
                m = wire.Rreq(rng.randrange(2**32), draw(addrs), 0, orig, rng.randrange(9),
                              rng.randrange(4), gratuitous=True, unknown_seq=True)  # fmt: skip
                ev = {"ev": "control", "now": now + k * 1e-4, "src": fsrc, "ttl": 5,
                      "bytes": m.encode().hex()}  # fmt: skip
                events.append(ev)
            now += 40 * 1e-4
    events.append({"ev": "dump"})
    return events


# == recorded from the in-memory medium ===================================================
class Stalled(Exception):
    """A core's timer left its deadline at `now`, again and again (see `recorded_sequences`)."""


class Recorder:
    """Stands in for a node's core in aodv.sim: records each event, then passes it on."""

    def __init__(self, core: Any, init: Event) -> None:
        self.core = core
        self.events: list[Event] = [init]
        self.stalls = 0

    def on_control(self, now: float, src: str, ttl: int, msg: wire.Message) -> list:
        raw = wire.encode(msg).hex()
        self.events.append({"ev": "control", "now": now, "src": src, "ttl": ttl, "bytes": raw})
        return self.core.on_control(now, src, ttl, msg)

    def on_no_route(self, now: float, src: str, dst: str, packet: bytes) -> list:
        ev = {"ev": "no_route", "now": now, "src": src, "dst": dst, "packet": packet.hex()}
        self.events.append(ev)
        return self.core.on_no_route(now, src, dst, packet)

    def on_route_used(self, now: float, addr: str) -> list:
        self.events.append({"ev": "route_used", "now": now, "addr": addr})
        return self.core.on_route_used(now, addr)

    def on_timer(self, now: float) -> list:
        self.events.append({"ev": "timer", "now": now})
        out = self.core.on_timer(now)
        if self.core.next_deadline() <= now:
            self.stalls += 1
            if self.stalls > 50:
                raise Stalled(now)
        else:
            self.stalls = 0
        return out

    def next_deadline(self) -> float:
        return self.core.next_deadline()


def record(m: Medium, addr: str, rebooted: bool = False) -> Recorder:
    """Add a node to the medium whose events are recorded."""
    node = m.add_node(addr, rebooted)
    init = {"ev": "init", "now": m.now, "addr": addr, "params": params_spec(m.p),
            "rebooted": rebooted, "seq": 0, "rreq_id": 0}  # fmt: skip
    rec = Recorder(node.core, init)
    node.core = rec  # type: ignore[assignment]
    return rec


@st.composite
def recorded_sequences(draw) -> list[list[Event]]:
    p = params_of(draw(param_specs()))
    m = Medium(p, hop_delay=draw(st.sampled_from([0.001, 0.0005, 0.003])))
    n = draw(st.integers(2, 6))
    names = POOL[:n]
    recs = [record(m, a, rebooted=draw(st.booleans()) and draw(st.booleans())) for a in names]
    for a, b in zip(names, names[1:], strict=False):
        m.link(a, b, both=draw(st.sampled_from([True, True, True, False])))
    for _ in range(draw(st.integers(0, 3))):
        a, b = draw(st.sampled_from(names)), draw(st.sampled_from(names))
        if a != b:
            m.link(a, b)
    span = 40.0 / p.time_scale
    for _ in range(draw(st.integers(1, 8))):
        t = draw(st.floats(0.0, span, allow_nan=False))
        a, b = draw(st.sampled_from(names)), draw(st.sampled_from(names))
        what = draw(st.sampled_from(["send", "send", "stream", "stream", "unlink", "link"]))
        if what == "send" and a != b:
            m.at(t, functools.partial(m.send_data, a, b))
        elif what == "stream" and a != b:  # data every 0.4 s for 8 s: routes stay active
            for k in range(20):
                m.at(t + k * 0.4 / p.time_scale, functools.partial(m.send_data, a, b))
        elif what == "unlink":
            m.at(t, functools.partial(m.unlink, a, b))
        elif what == "link" and a != b:
            m.at(t, functools.partial(m.link, a, b))
    try:
        m.run_until(span + draw(st.sampled_from([0.0, 20.0])) / p.time_scale)
    except Stalled as e:
        # A core that leaves its deadline at `now` for good wakes a daemon's loop again and
        # again. Two such rules were found here and fixed in both cores: RateLimit's trim
        # (aodv/state.py) asked `times[0] <= now - window` where its deadline was
        # `times[0] + window`, which rounding can make differ; Neighbors.lost forgot an
        # unmonitored neighbour only after (>) the deadline next_deadline gave it.
        raise AssertionError(f"a core's timer left its deadline at now = {e}") from None
    return [mutate(draw, r.events) for r in recs]


def mutate(draw, events: list[Event]) -> list[Event]:
    """Flip, cut, extend, drop, repeat or insert events of a recorded sequence."""
    events = [dict(ev) for ev in events]
    if draw(st.booleans()):
        return events
    if draw(st.booleans()):
        events[0].update(rebooted=True, seq=draw(seqs), rreq_id=draw(seqs))
    for _ in range(draw(st.integers(1, 6))):
        if len(events) < 2:
            break
        i = draw(st.integers(1, len(events) - 1))
        ev = events[i]
        how = draw(st.sampled_from(["flip", "cut", "extend", "ttl", "drop", "repeat", "insert"]))
        if how in ("flip", "cut", "extend", "ttl") and ev["ev"] == "control":
            raw = bytes.fromhex(ev["bytes"])
            if how in ("flip", "cut") and not raw:
                how = "extend"
            if how == "flip":
                k = draw(st.integers(0, len(raw) - 1))
                raw = raw[:k] + bytes([raw[k] ^ draw(st.integers(1, 255))]) + raw[k + 1 :]
            elif how == "cut":
                raw = raw[: draw(st.integers(0, len(raw) - 1))]
            elif how == "extend":
                raw += draw(st.sampled_from(EXTENSIONS))
            else:
                ev["ttl"] = draw(st.sampled_from([0, 1, 2, 255]))
            ev["bytes"] = raw.hex()
        elif how == "drop":
            del events[i]
        elif how == "repeat":
            events.insert(i, dict(ev))
        elif how == "insert" and "now" in ev:
            src = draw(st.sampled_from(POOL))
            raw = draw(messages(src))
            events.insert(i, {"ev": "control", "now": ev["now"], "src": src, "ttl": 1,
                              "bytes": raw.hex()})  # fmt: skip
    return events


# == the tests =============================================================================
DIFF_SETTINGS = settings(
    deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large]
)


@settings(DIFF_SETTINGS, max_examples=200)
@given(random_sequences())
def test_random_events_agree(core_binary, seq):
    compare(core_binary, seq)


@settings(DIFF_SETTINGS, max_examples=60)
@given(recorded_sequences())
def test_recorded_and_mutated_topologies_agree(core_binary, seqs):
    for s in seqs:
        compare(core_binary, s)


datagrams = st.one_of(
    st.binary(max_size=48),
    st.tuples(st.integers(0, 6), st.binary(max_size=48)).map(lambda t: bytes([t[0]]) + t[1]),
    st.sampled_from(POOL).flatmap(messages),
)


@settings(DIFF_SETTINGS, max_examples=150)
@given(st.lists(datagrams, min_size=1, max_size=30), st.booleans())
def test_decoder_decisions_agree(core_binary, raws, own):
    """The codec alone: the same MalformedPacket decisions and decoded fields (from our own
    address the core then ignores the message; from a neighbour it acts on it)."""
    me = POOL[0]
    events: list[Event] = [{"ev": "init", "now": 0.0, "addr": me}]
    for k, raw in enumerate(raws):
        src = me if own else POOL[1 + k % 3]
        events.append({"ev": "control", "now": k * 0.01, "src": src, "ttl": 1, "bytes": raw.hex()})
    compare(core_binary, events)


def chain_discovery() -> tuple[Medium, list[Recorder]]:
    m = Medium(Params())
    recs = [record(m, a) for a in POOL[:4]]
    for a, b in zip(POOL[:4], POOL[1:4], strict=False):
        m.link(a, b)
    m.send_data(POOL[0], POOL[3])
    m.run_until(3.0)
    return m, recs


def link_break() -> tuple[Medium, list[Recorder]]:
    m, recs = chain_discovery()
    for t in (3.5, 4.0, 4.5):
        m.at(t, lambda: m.send_data(POOL[0], POOL[3]))
    m.run_until(5.0)
    m.unlink(POOL[2], POOL[3])
    for t in (5.2, 5.4, 5.6):
        m.at(t, lambda: m.send_data(POOL[0], POOL[3]))
    m.run_until(12.0)
    return m, recs


def hello_loss() -> tuple[Medium, list[Recorder]]:
    m, recs = chain_discovery()
    m.unlink(POOL[0], POOL[1])
    m.run_until(40.0)
    return m, recs


def reboot_rule() -> tuple[Medium, list[Recorder]]:
    m = Medium(Params())
    recs = [record(m, POOL[0], rebooted=True), record(m, POOL[1]), record(m, POOL[2])]
    m.link(POOL[0], POOL[1])
    m.link(POOL[1], POOL[2])
    m.send_data(POOL[0], POOL[2])  # waits DELETE_PERIOD (15 s) before its RREQ
    m.at(1.0, lambda: m.send_data(POOL[1], POOL[0]))  # no RREP from the waiting node
    m.run_until(25.0)
    return m, recs


SCENARIOS = {
    "chain_discovery": chain_discovery,
    "link_break": link_break,
    "hello_loss": hello_loss,
    "reboot_rule": reboot_rule,
}


def scenario_events(name: str) -> list[list[Event]]:
    m, recs = SCENARIOS[name]()
    if name == "chain_discovery":
        assert [len(n.delivered) for n in m.nodes.values()] == [0, 0, 0, 1]
        assert {s.kind for s in m.log} >= {"RREQ", "RREP"}
    elif name == "link_break":
        assert m.sent("RERR"), "the break sent no RERR"
    elif name == "hello_loss":
        assert not m.nodes[POOL[0]].kernel, "node 1 kept routes through a silent neighbour"
    elif name == "reboot_rule":
        first = m.sent("RREQ", POOL[0])[0].time
        assert first >= Params().delete_period, "a rebooted node sent a RREQ while it waited"
        assert all(s.time >= first for s in m.sent("RREP", POOL[0]))
        assert m.nodes[POOL[0]].delivered or m.nodes[POOL[2]].delivered
    return [r.events + [{"ev": "dump"}] for r in recs]


@pytest.mark.parametrize("name", sorted(SCENARIOS))
def test_fixed_scenarios_agree(core_binary, name):
    for events in scenario_events(name):
        compare(core_binary, events)


def half_millisecond_lifetimes() -> list[Event]:
    """Lifetimes that land on exactly half a millisecond: the Lifetime field is rounded half
    to even (Python's round), 2.5 ms to 2 and 0.5 ms to 0."""
    me, nb, asker = POOL[0], POOL[1], POOL[2]
    events: list[Event] = [{"ev": "init", "now": 0.0, "addr": me, "params": {"profile": "rfc"}}]
    for k, life in enumerate([3, 1, 2, 5]):
        dest = f"10.0.1.{k + 1}"
        rrep = wire.Rrep(dest, 5, "10.0.2.1", life, 1)
        rreq = wire.Rreq(k + 1, dest, 5, f"10.0.3.{k + 1}", 1, 0, gratuitous=True)
        t0 = float(k)
        events.append({"ev": "control", "now": t0, "src": nb, "ttl": 64,
                       "bytes": rrep.encode().hex()})  # fmt: skip
        events.append({"ev": "control", "now": t0 + 0.0005, "src": asker, "ttl": 5,
                       "bytes": rreq.encode().hex()})  # fmt: skip
    return events + [{"ev": "dump"}]


def test_half_millisecond_lifetimes_agree(core_binary):
    events = half_millisecond_lifetimes()
    lines = list(run_python(events))
    rreps = [ln for ln in lines if '"dst":"10.0.0.3"' in ln and '"msg":"02' in ln]
    # 2.5 ms and 0.5 ms exactly (at t = 2 and 3 the subtraction is not exact: no tie).
    assert [int(json.loads(ln)["msg"][32:40], 16) for ln in rreps][:2] == [2, 0]
    compare(core_binary, events)


def rerr_over_255() -> list[Event]:
    """300 routes through one neighbour, each carrying a RREP on to another: the neighbour's
    loss invalidates them all (and the route to it) and the RERR goes out in two messages
    (255 + 46)."""
    me, via, back, orig = POOL[0], POOL[1], POOL[2], "10.0.9.9"
    events: list[Event] = [{"ev": "init", "now": 0.0, "addr": me, "params": {"profile": "ns3"}}]
    rreq = wire.Rreq(1, "10.0.5.5", 0, orig, 7, 2, unknown_seq=True)
    events.append({"ev": "control", "now": 0.0, "src": back, "ttl": 9,
                   "bytes": rreq.encode().hex()})  # fmt: skip
    for k in range(300):
        rrep = wire.Rrep(f"10.1.{k // 250}.{k % 250 + 1}", 3, orig, 5000, 1)
        events.append({"ev": "control", "now": 0.001 + k * 1e-5, "src": via, "ttl": 64,
                       "bytes": rrep.encode().hex()})  # fmt: skip
    events += [{"ev": "link_lost", "now": 0.5, "neighbor": via}, {"ev": "dump"}]
    return events


def test_rerr_over_255_destinations_agrees(core_binary):
    events = rerr_over_255()
    rerrs = [ln for ln in run_python(events) if '"msg":"03' in ln]
    assert [json.loads(ln)["msg"][6:8] for ln in rerrs] == ["ff", "2e"]
    compare(core_binary, events)


# Lines that are not events (each gets one "error" line, and the driver goes on).
GARBAGE = [
    "{",
    "[]",
    "nul\x00",
    '{"ev":"nope"}',
    '{"ev":"init","now":0,"addr":"10.0.0.256"}',
    '{"ev":"init","now":"x","addr":"10.0.0.1"}',
    '{"ev":"init","now":0,"addr":"10.0.0.1","params":{"ttl_increment":0}}',
    '{"ev":"init","now":0,"addr":"10.0.0.1","params":{"profile":"x"}}',
    '{"ev":"control","now":1,"src":"10.0.0.2","ttl":300,"bytes":"04"}',
    '{"ev":"control","now":1,"src":"10.0.0.2","ttl":1,"bytes":"0g"}',
    "[" * 10000,
    '{"a":' * 5000,
]


def test_driver_survives_any_line(core_binary):
    """A line that is not an event gets one "error" line; the driver goes on."""
    d = Driver(str(core_binary.binary))  # a fresh one: no core yet
    for line in ['{"ev":"timer"}', *GARBAGE]:
        got = d.feed(line)
        assert len(got) == 1 and got[0].startswith('{"error":'), (line[:40], got)
    assert d.feed('{"ev":"init","now":0,"addr":"10.0.0.1"}') == ['{"now":0,"next":1,"dropped":{}}']
    assert d.close() == 0


def run_python(events: list[Event]) -> list[str]:
    t = Trace()
    return [out for ev in events for out in t.feed(json.loads(json.dumps(ev)))]


def test_replay_tool_agrees_on_a_file(core_binary, tmp_path):
    """`python -m aodv.coretrace --against` replays an event file against both cores."""
    from aodv import coretrace

    path = tmp_path / "events.jsonl"
    events = [ev for seq in scenario_events("link_break") for ev in seq]
    path.write_text("".join(json.dumps(ev) + "\n" for ev in events))
    assert coretrace.main(["--against", str(BINARY), str(path)]) == 0


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("g++") is None, reason="g++ not found: no sanitizer build")
def test_sanitized_core_agrees():
    """The corpus (fixed scenarios and seeded random and recorded sequences) through the
    AddressSanitizer/UndefinedBehaviorSanitizer build: same output, no report (a report
    ends the process, which the comparison sees)."""
    reason = _build(ASAN_BINARY)
    if reason is not None:
        pytest.skip(reason)
    drivers = Drivers(ASAN_BINARY)
    try:
        for name in sorted(SCENARIOS):
            for events in scenario_events(name):
                compare(drivers, events)
        compare(drivers, half_millisecond_lifetimes())
        compare(drivers, rerr_over_255())
        for line in GARBAGE:
            assert drivers.get().feed(line)[0].startswith('{"error":')

        @settings(max_examples=150, derandomize=True, deadline=None,
                  suppress_health_check=list(HealthCheck))  # fmt: skip
        @given(st.one_of(random_sequences().map(lambda s: [s]), recorded_sequences()))
        def run(seqs):
            for s in seqs:
                compare(drivers, s)

        run()
    finally:
        drivers.close()
    assert drivers.driver is not None and drivers.driver.proc.returncode == 0


def test_zz_report():
    """How much was compared in this session (shown with pytest -s)."""
    print(f"\naodv differential: {dict(STATS)}")
