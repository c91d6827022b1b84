"""A robot namespace's network timers in emulated time: what to write, and what could not be.

Theory of operation. At time scale K the world runs K times faster than emulated time, and so
must every timer that belongs to it (docs/architecture.md, "Time dilation and fidelity"). The
kernel's network timers run on the wall clock: left alone, TCP's minimum retransmission
timeout of 200 ms lasts K x 200 ms of emulated time. A stock kernel has a knob for some of
them in every network namespace (sysctls); this module is the arithmetic, pure (no kernel is
read or written here; topology.radio.veth probes the namespace and writes what `plan` says):

- `KNOBS` lists the per-namespace sysctls that hold a network timer: TCP's retransmission
  timeout floor and ceiling (`tcp_rto_min_us`, Linux 6.11; `tcp_rto_max_ms`, 6.15), its SACK
  compression delay, FIN-WAIT-2, keepalive, TIME-WAIT reuse and rate-limit intervals, ICMP's
  rate limit, and the neighbour (ARP, IPv6 ND) timers of the robot's interface. Which of them
  a kernel has is found at run time: a key missing from the namespace is recorded as such.
- `dilate` divides a knob's default by K and rounds it to what the kernel can hold: a value the
  kernel keeps in jiffies is a whole number of jiffies (4 ms at HZ = 250), a value in seconds
  whole seconds, and the kernel's own floor and ceiling bound it (`tcp_rto_max_ms` takes
  nothing under 1000 ms). The TCP retransmission timer fires `RTO_OVERHEAD_JIFFIES` after its
  floor (the kernel rounds srtt + rttvar up to a jiffy, and its timer wheel fires a timer a
  jiffy late rather than early): measured at HZ = 250, a 24 ms RTO retransmitted after
  27.6 ms. So `tcp_rto_min_us` is chosen for (floor + overhead) x K to equal the default's
  floor + overhead, which at K = 10 and HZ = 250 is 3 jiffies (12 ms): a retransmission then
  waits 5 jiffies, 200 emulated ms, as at K = 1 it waits 52 jiffies, 208 ms.
- `FIXED` lists what no knob reaches, compiled into the kernel: the first timeout of a SYN or
  SYN-ACK (1 s), the delayed ACK's floor (40 ms; since Linux 6.11 capped at the RTO floor
  less a jiffy, so a dilated floor shortens it), the 2 ms floor of the tail loss probe and the
  millisecond clock of TCP timestamps. A per-route metric would reach some of them (`ip route
  ... quickack 1` turns delayed ACKs off), but routes belong to the routing daemon, which does
  not set them; what is set here holds whichever daemon installs the routes.

`plan(K, ...)` returns a `NetworkTimers`: one `Setting` per knob (its default, the value to
write, what that amounts to in emulated time, and whether it is dilated within `TOLERANCE`,
limited by the kernel, missing or refused) and one `FixedTimer` per compiled-in timer with
its wall and emulated length. result.json (`network_timers`) and `net up`'s network.json
carry it (`to_dict`); testbed.run.fidelity judges it (`tcp_dilated`). At K = 1 nothing is
written.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, replace

from common import timescale

TOLERANCE = 0.25  # an emulated value within 25% of the default counts as dilated
RTO_OVERHEAD_JIFFIES = 2  # how much later than its floor TCP's retransmission timer fires
UNIT_US = {"ns": 0.001, "us": 1.0, "ms": 1000.0, "s": 1_000_000.0}
DEV = "{dev}"  # stands for the robot's interface in a per-interface key

# Statuses of a Setting.
DEFAULT = "default"  # time scale 1: the kernel's value, untouched
DILATED = "dilated"  # written; K x it is within TOLERANCE of the default
LIMITED = "limited"  # written, but the kernel's floor, ceiling or granularity kept it off
MISSING = "missing"  # this kernel has no such sysctl
REFUSED = "refused"  # the kernel refused the value


@dataclass(frozen=True)
class Knob:
    """A per-namespace sysctl that holds a network timer."""

    name: str  # the record's name for it
    key: str  # the sysctl; DEV stands for the robot's interface
    unit: str  # what its number counts: "ns", "us", "ms" or "s"
    jiffies: bool  # the kernel keeps it in jiffies (its granularity)
    minimum: int  # the smallest value the kernel takes, in `unit`
    maximum: int | None  # the largest, when the kernel has a ceiling under INT_MAX
    what: str
    since: str = ""  # the first Linux release that has it, when that is recent
    overhead_jiffies: int = 0  # the timer fires this much after the value (see above)

    def sysctl(self, dev: str) -> str:
        return self.key.replace(DEV, dev)


_NEIGH = (
    ("retrans_time_ms", "ms", True, "between {fam} neighbour probes (ARP or ND retransmit)"),
    ("base_reachable_time_ms", "ms", True, "a {fam} neighbour stays reachable (base)"),
    ("delay_first_probe_time", "s", True, "a stale {fam} neighbour waits before a probe"),
    ("gc_stale_time", "s", True, "a stale {fam} neighbour is kept before collection"),
)

KNOBS: tuple[Knob, ...] = (
    Knob("tcp_rto_min", "net.ipv4.tcp_rto_min_us", "us", True, 1, None,
         "TCP's minimum retransmission timeout", "6.11", RTO_OVERHEAD_JIFFIES),
    Knob("tcp_rto_max", "net.ipv4.tcp_rto_max_ms", "ms", True, 1000, 120_000,
         "TCP's maximum retransmission timeout (its backoff's ceiling)", "6.15"),
    Knob("tcp_comp_sack_delay", "net.ipv4.tcp_comp_sack_delay_ns", "ns", False, 0, None,
         "how long TCP may hold back a SACK to compress it"),
    Knob("tcp_comp_sack_slack", "net.ipv4.tcp_comp_sack_slack_ns", "ns", False, 0, None,
         "the slack of TCP's SACK compression timer", "6.6"),
    Knob("tcp_fin_timeout", "net.ipv4.tcp_fin_timeout", "s", True, 1, None,
         "how long an orphaned TCP connection stays in FIN-WAIT-2"),
    Knob("tcp_keepalive_time", "net.ipv4.tcp_keepalive_time", "s", True, 1, None,
         "TCP's idle time before the first keepalive (sockets that ask for them)"),
    Knob("tcp_keepalive_intvl", "net.ipv4.tcp_keepalive_intvl", "s", True, 1, None,
         "TCP's interval between keepalives"),
    Knob("tcp_tw_reuse_delay", "net.ipv4.tcp_tw_reuse_delay", "ms", False, 1, None,
         "how long a TIME-WAIT connection waits before its port may be reused", "6.13"),
    Knob("tcp_invalid_ratelimit", "net.ipv4.tcp_invalid_ratelimit", "ms", True, 0, None,
         "TCP's rate limit on answers to invalid segments"),
    Knob("icmp_ratelimit", "net.ipv4.icmp_ratelimit", "ms", True, 0, None,
         "the rate limit on ICMP errors (a forwarded packet's 'host unreachable')"),
    *(
        Knob(f"{fam}_neigh_{leaf.removesuffix('_ms')}", f"net.{fam}.neigh.{DEV}.{leaf}", unit,
             jiffies, 1, None, what.format(fam=fam.replace("ip", "IP")))
        for fam in ("ipv4", "ipv6")
        for leaf, unit, jiffies, what in _NEIGH
    ),
)  # fmt: skip

BY_NAME = {k.name: k for k in KNOBS}


@dataclass(frozen=True)
class Setting:
    """What became of one knob in a robot namespace. Values in the knob's unit; `emulated`
    is what the written value lasts in emulated time (value x K, with the kernel's overhead)."""

    name: str
    key: str
    unit: str
    default: int | None  # the namespace's value before (None: missing)
    value: int | None  # written (the default at time scale 1; None: missing or refused)
    emulated: float | None
    status: str
    note: str = ""


@dataclass(frozen=True)
class FixedTimer:
    """A network timer compiled into the kernel, which no per-namespace knob reaches."""

    name: str
    what: str
    wall_ms: float  # how long it lasts on the wall clock (in this namespace)
    emulated_ms: float  # ... in emulated time: wall_ms x K


@dataclass(frozen=True)
class NetworkTimers:
    """The network timers of a testbed's robot namespaces at one time scale."""

    time_scale: float
    kernel: str  # the release (uname -r)
    jiffy_us: int | None  # the kernel's timer granularity, as probed (None: not known)
    settings: tuple[Setting, ...]
    fixed: tuple[FixedTimer, ...]

    def setting(self, name: str) -> Setting | None:
        return next((s for s in self.settings if s.name == name), None)

    def writes(self) -> list[tuple[str, int]]:
        """(sysctl, value) to write in each robot namespace; none at time scale 1."""
        return [
            (s.key, s.value)
            for s in self.settings
            if s.status in (DILATED, LIMITED) and s.value is not None
        ]

    @property
    def tcp_dilated(self) -> bool:
        """Whether TCP's retransmission timer runs in emulated time: at time scale 1 by
        definition, else when its floor was dilated within TOLERANCE."""
        if self.time_scale == 1:
            return True
        rto = self.setting("tcp_rto_min")
        return rto is not None and rto.status == DILATED

    @property
    def tcp_reason(self) -> str:
        """Why TCP's retransmission timer is not in emulated time ("" when it is)."""
        if self.tcp_dilated:
            return ""
        rto = self.setting("tcp_rto_min")
        why = rto.note if rto is not None else "no record of net.ipv4.tcp_rto_min_us"
        return (
            f"TCP's retransmission timeout is not dilated at time scale {self.time_scale:g}: {why}"
        )

    @property
    def not_dilated(self) -> list[str]:
        """The names of the timers that do not run in emulated time (none at time scale 1)."""
        if self.time_scale == 1:
            return []
        off = [s.name for s in self.settings if s.status not in (DILATED, DEFAULT)]
        return off + [f.name for f in self.fixed]

    def summary(self) -> str:
        """One line for a person: what is dilated and what is not."""
        if self.time_scale == 1:
            return "network timers: time scale 1, the kernel's own"
        ok = [s.name for s in self.settings if s.status == DILATED]
        rto = self.setting("tcp_rto_min")
        head = f"network timers at time scale {self.time_scale:g}: {len(ok)} dilated"
        if (
            rto is not None
            and rto.status == DILATED
            and rto.value is not None
            and rto.emulated is not None
        ):
            head += (
                f" (TCP's RTO floor {rto.value / 1000:g} ms: {rto.emulated / 1000:.0f} emulated)"
            )
        return head + f"; not dilated: {', '.join(self.not_dilated) or 'none'}"

    def to_dict(self) -> dict:
        return {
            "time_scale": self.time_scale,
            "kernel": self.kernel,
            "jiffy_us": self.jiffy_us,
            "tcp_dilated": self.tcp_dilated,
            "settings": [asdict(s) for s in self.settings],
            "fixed": [asdict(f) for f in self.fixed],
        }

    @classmethod
    def from_dict(cls, d: Mapping) -> NetworkTimers:
        """The inverse of to_dict (ValueError for a dict that is not one)."""
        try:
            return cls(
                time_scale=float(d["time_scale"]),
                kernel=str(d["kernel"]),
                jiffy_us=None if d.get("jiffy_us") is None else int(d["jiffy_us"]),
                settings=tuple(Setting(**s) for s in d["settings"]),
                fixed=tuple(FixedTimer(**f) for f in d["fixed"]),
            )
        except (KeyError, TypeError) as e:
            raise ValueError(f"not a network timers record: {e}") from None


# -- the arithmetic ---------------------------------------------------------------------------


def granularity(knob: Knob, jiffy_us: int) -> float:
    """The step, in the knob's unit, between values the kernel can hold."""
    step = 1.0
    if knob.jiffies:
        step = max(step, jiffy_us / UNIT_US[knob.unit])
    return step


def dilate(knob: Knob, default: int, time_scale: float, jiffy_us: int) -> tuple[int, float]:
    """(the value to write, what it lasts in emulated time), both in the knob's unit: the
    default divided by the time scale, on the kernel's granularity, within its limits. A timer
    that fires `overhead_jiffies` after its value is dilated as value + overhead."""
    if timescale.refusal(time_scale):
        raise ValueError(timescale.refusal(time_scale))
    step = granularity(knob, jiffy_us)
    over = knob.overhead_jiffies * jiffy_us / UNIT_US[knob.unit]
    target = (default + over) / time_scale - over
    value = math.floor(target / step + 0.5) * step  # the nearest step, halves up
    value = max(value, knob.minimum, step)  # a positive timer never becomes 0
    if knob.maximum is not None:
        value = min(value, knob.maximum)
    value = round(value)
    return value, (value + over) * time_scale - over


def _setting(knob: Knob, dev: str, default: int | None, time_scale: float, jiffy_us: int):
    key = knob.sysctl(dev)
    if default is None:
        since = f" (Linux {knob.since} and later)" if knob.since else ""
        return Setting(knob.name, key, knob.unit, None, None, None, MISSING,
                       f"this kernel has no {key}{since}")  # fmt: skip
    if time_scale == 1 or default <= 0:
        return Setting(knob.name, key, knob.unit, default, default, float(default), DEFAULT)
    value, emulated = dilate(knob, default, time_scale, jiffy_us)
    if abs(emulated - default) <= TOLERANCE * default:
        return Setting(knob.name, key, knob.unit, default, value, emulated, DILATED)
    step = granularity(knob, jiffy_us)
    if knob.maximum is not None and value >= knob.maximum:
        why = f"the kernel's ceiling of {knob.maximum} {knob.unit}"
    elif value <= max(knob.minimum, step):
        why = f"the kernel's floor of {round(max(knob.minimum, step))} {knob.unit}"
        if step > knob.minimum and knob.unit != "s":
            why += f" (one jiffy, {jiffy_us} us)"
    else:
        why = f"the kernel's granularity of {step:g} {knob.unit}"
    shown = f"{emulated:.0f}" if emulated >= 10 else f"{emulated:.3g}"
    note = f"{value} {knob.unit} lasts {shown} emulated {knob.unit} instead of {default}: {why}"
    return Setting(knob.name, key, knob.unit, default, value, emulated, LIMITED, note)


def fixed_timers(time_scale: float, jiffy_us: int, rto_min: Setting | None) -> tuple:
    """The compiled-in timers and what they last at this time scale (none at 1)."""
    if time_scale == 1:
        return ()
    delack_ms = 40.0  # TCP_ATO_MIN
    capped = ""
    if rto_min is not None and rto_min.value is not None:
        # Since Linux 6.11 (the release of tcp_rto_min_us) the delayed ACK waits at most one
        # jiffy less than the RTO floor (tcp_delack_max).
        rto_jiffies = math.ceil(rto_min.value / jiffy_us)
        delack_ms = min(delack_ms, (max(rto_jiffies, 2) - 1) * jiffy_us / 1000)
        capped = "; capped at the RTO floor less a jiffy"
    rows = (
        ("tcp_syn_rto", "the first retransmission timeout of a SYN or SYN-ACK (3 s after a "
         "handshake that needed one)", 1000.0),
        ("tcp_delayed_ack", f"the delayed ACK's wait (40 ms floor{capped})", delack_ms),
        ("tcp_probe_floor", "the floor of the tail loss probe and the RACK reordering timer",
         2.0),
        ("tcp_timestamp_clock", "the tick of TCP timestamps, the floor of an RTT sample taken "
         "from them", 1.0),
    )  # fmt: skip
    return tuple(FixedTimer(n, w, round(ms, 3), round(ms * time_scale, 3)) for n, w, ms in rows)


def plan(
    time_scale: float,
    defaults: Mapping[str, int],
    jiffy_us: int,
    kernel: str = "",
    dev: str = "wlan0",
) -> NetworkTimers:
    """What to write in a robot namespace at this time scale. `defaults` maps each sysctl the
    namespace has to its value there (a key it lacks is missing); `jiffy_us` is the kernel's
    jiffy (topology.radio.veth probes it)."""
    if timescale.refusal(time_scale):
        raise ValueError(timescale.refusal(time_scale))
    if jiffy_us <= 0:
        raise ValueError(f"a jiffy lasts a positive time, not {jiffy_us} us")
    settings = tuple(
        _setting(k, dev, defaults.get(k.sysctl(dev)), time_scale, jiffy_us) for k in KNOBS
    )
    rto = next(s for s in settings if s.name == "tcp_rto_min")
    return NetworkTimers(
        time_scale=time_scale, kernel=kernel, jiffy_us=jiffy_us, settings=settings,
        fixed=fixed_timers(time_scale, jiffy_us, rto if rto.status != MISSING else None),
    )  # fmt: skip


def refused(timers: NetworkTimers, key: str, error: str) -> NetworkTimers:
    """`timers` with the setting of `key` marked as refused by the kernel."""
    settings = tuple(
        replace(s, value=None, emulated=None, status=REFUSED, note=f"the kernel refused "
                f"{s.value} {s.unit} for {key}: {error}")
        if s.key == key else s
        for s in timers.settings
    )  # fmt: skip
    return replace(timers, settings=settings)
