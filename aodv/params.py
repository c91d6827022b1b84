"""Protocol parameters of RFC 3561 section 10, as one frozen dataclass.

Inputs are fields with the RFC's defaults (times in RFC milliseconds); every derived value is
a property computed from its inputs, so changing an input can never leave a copy stale (the
inputs are frozen, so each is computed once and cached: the core reads them on every hop).
Every time the core uses is in seconds of the run's clock and divided by `time_scale`: a
run at time scale K runs all protocol timers K times faster.

Decision (MY_ROUTE_TIMEOUT): the section 10 table gives 2 * ACTIVE_ROUTE_TIMEOUT (6 s);
ns-3 uses 11.2 s (2 * max(PATH_DISCOVERY_TIME, ACTIVE_ROUTE_TIMEOUT)). We follow the table.
Decision (DELETE_PERIOD): section 10 note, K = 5 times max(ACTIVE_ROUTE_TIMEOUT,
HELLO_INTERVAL) since hellos are used (link-layer feedback is not available here).
Decision (MIN_REPAIR_TTL): local repair is not implemented, so it is not defined.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property


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
    ttl_start: int = 1
    ttl_increment: int = 2
    ttl_threshold: int = 7
    delete_period_k: int = 5
    # Not in section 10: bounds of the data packet buffer of section 6.3 (ns-3 uses 64).
    queue_len: int = 64
    # Section 6.3 "SHOULD set the G flag" when the route is used bidirectionally: our
    # traffic (ping, TCP) always is, so by default every RREQ asks for a gratuitous RREP.
    gratuitous_rrep: bool = True
    dest_only: bool = False

    def __post_init__(self) -> None:
        if not self.time_scale > 0:
            raise ValueError(f"time_scale must be > 0, not {self.time_scale}")

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
        """RREQ_RETRIES * NET_TRAVERSAL_TIME."""
        return self.rreq_retries * self.net_traversal_time

    @cached_property
    def delete_period(self) -> float:
        """K * max(ACTIVE_ROUTE_TIMEOUT, HELLO_INTERVAL), K = 5."""
        return self.delete_period_k * max(self.active_route_timeout, self.hello_interval)

    @cached_property
    def my_route_timeout(self) -> float:
        """2 * ACTIVE_ROUTE_TIMEOUT."""
        return 2 * self.active_route_timeout

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
        """Scaled seconds to the RFC milliseconds carried in a Lifetime field."""
        return max(0, int(round(seconds * self.time_scale * 1000)))

    def from_ms(self, ms: int) -> float:
        """A Lifetime field (RFC milliseconds) to scaled seconds."""
        return self._s(ms)
