"""Protocol parameters of RFC 3561 section 10, as one frozen dataclass, and named profiles.

Inputs are fields with the RFC's defaults (times in RFC milliseconds); every derived value is
a property computed from its inputs, so changing an input can never leave a copy stale (the
inputs are frozen, so each is computed once and cached: the core reads them on every hop).
Every time the core uses is in seconds of the run's clock and divided by `time_scale`: a
run at time scale K runs all protocol timers K times faster.

Where the section 10 table and its notes disagree, the notes win, because they are the
constraints the table's formulas forget (`Params.problems()` checks them at start):

- MY_ROUTE_TIMEOUT: the table gives 2 * ACTIVE_ROUTE_TIMEOUT (6 s), but section 10 says
  "the configured value for MY_ROUTE_TIMEOUT MUST be at least 2 * PATH_DISCOVERY_TIME"
  (11.2 s with the defaults). Default: the larger of the two, 11.2 s (ns-3's value too).
- BLACKLIST_TIMEOUT: the table gives RREQ_RETRIES * NET_TRAVERSAL_TIME (5.6 s); the note
  says it "should be suitably increased if an expanding ring search is used. In such cases,
  it should be {[(TTL_THRESHOLD - TTL_START)/TTL_INCREMENT] + 1 + RREQ_RETRIES} *
  NET_TRAVERSAL_TIME." We use the ring search: default 5 * 2.8 = 14 s (TTL_START 2).
- TTL_START: the table gives 1; the note says it "should be set to at least 2 if Hello
  messages are used for local connectivity information". We use HELLOs: default 2.
- DELETE_PERIOD: the note's K = 5 times max(ACTIVE_ROUTE_TIMEOUT, HELLO_INTERVAL), since
  HELLOs are used (link-layer feedback is not available here).
- Local repair (6.12) is optional in the RFC and on by default here (robots move);
  MIN_REPAIR_TTL is "the last known hop count to the destination", per route.

Profiles (`PROFILES`, `--aodv-profile`): `rfc` is the above; `ns3` is ns-3's AODV model
defaults (MyRouteTimeout 11.2 s, BlackListTimeout 5.6 s, TtlStart 1, no local repair, which
ns-3 does not implement), so results can be set beside ns-3 studies.

Not in section 10, bounds against a flood of forged messages (RFC 3561 sets none): the
routing table, the RREQ cache and the neighbour list are bounded (`*_limit`), and forwarded
RREQs are rate-limited like originated ones (`rreq_forward_ratelimit` per second).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

MAX_TTL = 255  # an IP TTL and an AODV hop count are one byte


@dataclass(frozen=True)
class Params:
    time_scale: float = 1.0
    active_route_timeout_ms: float = 3000
    allowed_hello_loss: int = 2
    hello_interval_ms: float = 1000
    local_add_ttl: int = 2
    net_diameter: int = 35
    node_traversal_time_ms: float = 40
    rerr_ratelimit: int = 10
    rreq_retries: int = 2
    rreq_ratelimit: int = 10
    timeout_buffer: int = 2
    ttl_start: int = 2
    ttl_increment: int = 2
    ttl_threshold: int = 7
    delete_period_k: int = 5
    # None: the section 10 rules above; a number overrides (a profile's fixed value).
    my_route_timeout_ms: float | None = None
    blacklist_timeout_ms: float | None = None
    local_repair: bool = True
    # Not in section 10: bounds of the data packet buffer of section 6.3 (ns-3 uses 64).
    queue_len: int = 64
    # Section 6.3 "SHOULD set the G flag" when the route is used bidirectionally: our
    # traffic (ping, TCP) always is, so by default every RREQ asks for a gratuitous RREP.
    gratuitous_rrep: bool = True
    dest_only: bool = False
    # Not in RFC 3561: bounds against a flood (see the module docstring).
    route_table_limit: int = 1024
    rreq_cache_limit: int = 4096
    neighbor_limit: int = 256
    rreq_forward_ratelimit: int = 100

    def __post_init__(self) -> None:
        if not self.time_scale > 0:
            raise ValueError(f"time_scale must be > 0, not {self.time_scale}")

    def problems(self) -> list[str]:
        """The section 10 constraints (and plain sanity) these values break; [] if none."""
        out = []
        for name in ("active_route_timeout_ms", "hello_interval_ms", "node_traversal_time_ms"):
            if not getattr(self, name) > 0:
                out.append(f"{name} must be > 0")
        for name in ("allowed_hello_loss", "ttl_start", "ttl_increment", "delete_period_k"):
            if getattr(self, name) < 1:
                out.append(f"{name} must be >= 1")
        if not self.ttl_start <= self.ttl_threshold <= self.net_diameter <= MAX_TTL:
            out.append(
                "TTL_START <= TTL_THRESHOLD <= NET_DIAMETER <= 255 must hold "
                f"({self.ttl_start}, {self.ttl_threshold}, {self.net_diameter})"
            )
        # Section 10: "the configured value for MY_ROUTE_TIMEOUT MUST be at least
        # 2 * PATH_DISCOVERY_TIME."
        if self.my_route_timeout < 2 * self.path_discovery_time - 1e-9:
            out.append(
                f"MY_ROUTE_TIMEOUT ({self.ms(self.my_route_timeout)} ms) must be at least "
                f"2 * PATH_DISCOVERY_TIME ({self.ms(2 * self.path_discovery_time)} ms)"
            )
        # Section 6.11: DELETE_PERIOD bounds how long a neighbour may keep us as next hop
        # after we invalidated a route; it cannot be shorter than the HELLO loss detection.
        if self.delete_period < self.neighbor_timeout:
            out.append("DELETE_PERIOD must be at least ALLOWED_HELLO_LOSS * HELLO_INTERVAL")
        for name in ("rreq_ratelimit", "rerr_ratelimit", "rreq_forward_ratelimit", "queue_len"):
            if getattr(self, name) < 1:
                out.append(f"{name} must be >= 1")
        for name in ("route_table_limit", "rreq_cache_limit", "neighbor_limit"):
            if getattr(self, name) < 16:
                out.append(f"{name} must be >= 16")
        return out

    def _s(self, ms: float) -> float:
        """RFC milliseconds to scaled seconds of the run's clock."""
        return ms / 1000.0 / self.time_scale

    # -- times in scaled seconds ------------------------------------------------------
    @cached_property
    def active_route_timeout(self) -> float:
        return self._s(self.active_route_timeout_ms)

    @cached_property
    def hello_interval(self) -> float:
        return self._s(self.hello_interval_ms)

    @cached_property
    def node_traversal_time(self) -> float:
        return self._s(self.node_traversal_time_ms)

    @cached_property
    def net_traversal_time(self) -> float:
        """2 * NODE_TRAVERSAL_TIME * NET_DIAMETER."""
        return 2 * self.node_traversal_time * self.net_diameter

    @cached_property
    def path_discovery_time(self) -> float:
        """2 * NET_TRAVERSAL_TIME."""
        return 2 * self.net_traversal_time

    @cached_property
    def blacklist_timeout(self) -> float:
        """The section 10 note for the expanding ring search (module docstring)."""
        if self.blacklist_timeout_ms is not None:
            return self._s(self.blacklist_timeout_ms)
        rings = (self.ttl_threshold - self.ttl_start) // self.ttl_increment + 1
        return (rings + self.rreq_retries) * self.net_traversal_time

    @cached_property
    def delete_period(self) -> float:
        """K * max(ACTIVE_ROUTE_TIMEOUT, HELLO_INTERVAL), K = 5."""
        return self.delete_period_k * max(self.active_route_timeout, self.hello_interval)

    @cached_property
    def my_route_timeout(self) -> float:
        """max(2 * ACTIVE_ROUTE_TIMEOUT, 2 * PATH_DISCOVERY_TIME) (module docstring)."""
        if self.my_route_timeout_ms is not None:
            return self._s(self.my_route_timeout_ms)
        return 2 * max(self.active_route_timeout, self.path_discovery_time)

    @cached_property
    def next_hop_wait(self) -> float:
        """NODE_TRAVERSAL_TIME + 10 ms."""
        return self.node_traversal_time + self._s(10)

    @cached_property
    def neighbor_timeout(self) -> float:
        """ALLOWED_HELLO_LOSS * HELLO_INTERVAL (sections 6.9, 6.10)."""
        return self.allowed_hello_loss * self.hello_interval

    @cached_property
    def max_repair_ttl(self) -> int:
        """0.3 * NET_DIAMETER."""
        return int(0.3 * self.net_diameter)

    @cached_property
    def rate_window(self) -> float:
        """The 'per second' of RREQ_RATELIMIT and RERR_RATELIMIT, scaled."""
        return self._s(1000)

    def ring_traversal_time(self, ttl: int) -> float:
        """2 * NODE_TRAVERSAL_TIME * (TTL_VALUE + TIMEOUT_BUFFER)."""
        return 2 * self.node_traversal_time * (ttl + self.timeout_buffer)

    def ms(self, seconds: float) -> int:
        """Scaled seconds to the RFC milliseconds carried in a Lifetime field (32 bits)."""
        return min(0xFFFFFFFF, max(0, int(round(seconds * self.time_scale * 1000))))

    def from_ms(self, ms: float) -> float:
        """A Lifetime field (RFC milliseconds) to scaled seconds."""
        return self._s(ms)


# ns-3's AODV model (src/aodv/model/aodv-routing-protocol.cc) attribute defaults, where they
# differ from the `rfc` profile. Everything else (timers, TTLs, rate limits, G flag, HELLOs,
# queue of 64) is the same in both.
NS3_DEFAULTS = {
    "my_route_timeout_ms": 11200,
    "blacklist_timeout_ms": 5600,
    "ttl_start": 1,
    "local_repair": False,
}
PROFILES: dict[str, dict] = {"rfc": {}, "ns3": NS3_DEFAULTS}


def profile(name: str, time_scale: float = 1.0) -> Params:
    """The named parameter set at a time scale; ValueError for an unknown name."""
    if name not in PROFILES:
        raise ValueError(f"unknown AODV profile {name!r} (choose from {', '.join(PROFILES)})")
    return replace(Params(time_scale=time_scale), **PROFILES[name])
