"""A testbed described as plain data: robots, positions, range model, impairments, routing.

Nothing here touches the kernel (docs/architecture.md: describe first, build second). The
`layout_positions` helpers turn the CLI's `--layout` into positions.
"""

import math
import random
from dataclasses import dataclass, field

from common import timescale
from topology import names

# The routing protocols, from topology.protocols' registry; the first is the default.
from topology.protocols import ROUTINGS as ROUTINGS

RANGE_MODELS = ("disc", "lossy", "los", "los-lossy")
LOS_MODELS = ("los", "los-lossy")  # the models that need a map's walls (topology.radio.los)
# aodv.params.PROFILES (topology imports nothing of aodv; a unit test keeps the two equal).
AODV_PROFILES = ("rfc", "ns3")
# Which AODV daemon runs (topology.routing): the Python reference or the compiled one. A run's
# `--aodv-daemon auto` is decided before a spec is made (testbed.run.daemonchoice).
AODV_DAEMONS = ("python", "cpp")
LAYOUTS = ("chain", "grid", "random")
# The radio medium (topology.radio.veth: veth links; topology.radio.ns3wifi: ns-3's 802.11) and, for
# ns3-wifi, its propagation (a cut-off at the range, or log-distance) and 802.11 standard.
VETH, NS3_WIFI = "veth", "ns3-wifi"
MEDIA = (VETH, NS3_WIFI)  # the first is the default
WIFI_LOSSES = ("range", "logdistance")
WIFI_STANDARDS = ("80211a", "80211b", "80211g")
# Metres per map cell: the robots' and the world's grid, and a pixel of the shipped maps (the
# default of --map-cell). Declared here, the lowest layer that needs it (the los walls' map).
CELL_M = 0.05


def _choice(value, choices: tuple[str, ...], what: str) -> None:
    """ValueError naming the choices unless `value` is one of them."""
    if value not in choices:
        raise ValueError(f"unknown {what} {value!r} (choose from {', '.join(choices)})")


def _number(value, what: str) -> float:
    """`value` if it is a number (an int or a float, not a bool), else ValueError saying
    so: a string "5" is refused in one sentence, not compared into a TypeError."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"{what} must be a number, not {str(value)[:40]!r}")
    return value


@dataclass(frozen=True)
class Impairment:
    """What one direction of one link does to frames: loss, delay, jitter, rate."""

    loss_pct: float = 0.0
    delay_ms: float = 0.0
    jitter_ms: float = 0.0
    rate_kbit: float = 0.0  # 0: unlimited

    def __post_init__(self) -> None:
        if not 0.0 <= _number(self.loss_pct, "loss") <= 100.0:
            raise ValueError(f"loss {self.loss_pct}% is not in 0..100")
        for what, value in (
            ("delay", self.delay_ms),
            ("jitter", self.jitter_ms),
            ("rate", self.rate_kbit),
        ):
            if _number(value, what) < 0 or not math.isfinite(value):
                raise ValueError(f"{what} {value} must be a finite number >= 0")

    @property
    def is_none(self) -> bool:
        return not (self.loss_pct or self.delay_ms or self.jitter_ms or self.rate_kbit)

    def scaled(self, time_scale: float) -> "Impairment":
        """Emulated time runs time_scale times faster than the wall clock: so do delays."""
        if time_scale == 1.0:
            return self
        return Impairment(
            loss_pct=self.loss_pct,
            delay_ms=self.delay_ms / time_scale,
            jitter_ms=self.jitter_ms / time_scale,
            rate_kbit=self.rate_kbit * time_scale,
        )

    def combined(self, other: "Impairment") -> "Impairment":
        """Both impairments in series: losses compound, delays add, the slower rate wins."""
        if other.is_none:
            return self
        if self.is_none:
            return other
        keep = (1 - self.loss_pct / 100) * (1 - other.loss_pct / 100)
        rates = [r for r in (self.rate_kbit, other.rate_kbit) if r > 0]
        return Impairment(
            loss_pct=round(100 * (1 - keep), 6),
            delay_ms=self.delay_ms + other.delay_ms,
            jitter_ms=self.jitter_ms + other.jitter_ms,
            rate_kbit=min(rates) if rates else 0.0,
        )


NO_IMPAIRMENT = Impairment()

Position = tuple[float, float]

# Coordinates are metres, at most this far from the origin on either axis: 10,000 km holds
# any projected coordinate on Earth (UTM eastings and northings included) at a resolution of
# nanometres, and keeps every difference, square and sum that the range models, the view and
# the ns-3 medium compute from positions finite (1e308 would overflow to infinity there).
MAX_COORD_M = 1e7


def check_position(xy, what: str = "position") -> Position:
    """`xy` as (x, y) floats if it is two finite numbers within MAX_COORD_M, else ValueError."""
    try:
        x, y = xy
        fx, fy = float(x), float(y)
    except (TypeError, ValueError):
        shown = " ".join(str(v)[:40] for v in xy) if isinstance(xy, list | tuple) else "?"
        raise ValueError(f"{what} ({shown}) is not two numbers") from None
    if not (math.isfinite(fx) and math.isfinite(fy)):
        raise ValueError(f"{what} ({fx:g}, {fy:g}) must be finite")
    if abs(fx) > MAX_COORD_M or abs(fy) > MAX_COORD_M:
        raise ValueError(f"{what} ({fx:g}, {fy:g}) is beyond {MAX_COORD_M:,.0f} m of 0")
    return fx, fy


@dataclass(frozen=True)
class NetworkSpec:
    """Everything needed to build one testbed's network."""

    name: str
    positions: tuple[Position, ...]
    comm_range: float
    routing: str = "none"
    impairment: Impairment = field(default_factory=Impairment)
    range_model: str = "disc"
    capture_dir: str | None = None
    time_scale: float = 1.0
    aodv_profile: str = "rfc"  # aodv.params.PROFILES; used only with routing "aodv"
    aodv_daemon: str = "python"  # AODV_DAEMONS; used only with routing "aodv"
    # Wall seconds between rewrites of each AODV daemon's statistics file (its --stats-period;
    # 0: written when ready, when asked with SIGUSR1 and as it stops, so an idle daemon sleeps).
    aodv_stats_period: float = 1.0
    # The walls of the los range models (topology.radio.los): a PNG, metres per pixel, and the
    # loss a wall costs (None: a wall blocks).
    map_png: str | None = None
    map_cell: float = CELL_M
    wall_loss_pct: float | None = None
    medium: str = VETH  # MEDIA
    wifi_loss: str = "range"  # the ns3-wifi medium's propagation (WIFI_LOSSES)
    wifi_standard: str = "80211a"
    wifi_rate: str = ""  # ns3-wifi: an ns-3 WifiMode name, "minstrel", or "": the fastest

    def __post_init__(self) -> None:
        names.check_name(self.name)
        if not isinstance(self.positions, list | tuple):
            raise ValueError(f"positions must be a tuple of (x, y), not {str(self.positions)[:40]}")
        if self.capture_dir is not None and not isinstance(self.capture_dir, str):
            raise ValueError(f"capture_dir must be a path (str), not {str(self.capture_dir)[:40]}")
        if not self.positions:
            raise ValueError("a testbed needs at least one robot")
        if len(self.positions) > names.MAX_ROBOTS:
            raise ValueError(f"at most {names.MAX_ROBOTS} robots")
        object.__setattr__(
            self,
            "positions",
            tuple(check_position(p, f"position of r{k}") for k, p in enumerate(self.positions, 1)),
        )
        if not (_number(self.comm_range, "communication range") > 0
                and math.isfinite(self.comm_range)):  # fmt: skip
            raise ValueError(
                f"communication range must be a positive number, not {self.comm_range}"
            )
        _choice(self.routing, ROUTINGS, "routing")
        _choice(self.range_model, RANGE_MODELS, "range model")
        if timescale.refusal(_number(self.time_scale, "time scale")):
            raise ValueError(timescale.refusal(self.time_scale))
        if not (_number(self.map_cell, "map cell size") > 0 and math.isfinite(self.map_cell)):
            raise ValueError(f"map cell size must be a positive number, not {self.map_cell}")
        if (
            self.wall_loss_pct is not None
            and not 0 <= _number(self.wall_loss_pct, "wall loss") <= 100
        ):
            raise ValueError(f"wall loss {self.wall_loss_pct}% is not in 0..100")
        _choice(self.medium, MEDIA, "medium")
        if self.medium == "ns3-wifi":
            _check_wifi(self)
        _choice(self.aodv_profile, AODV_PROFILES, "AODV profile")
        if not (math.isfinite(self.aodv_stats_period) and self.aodv_stats_period >= 0):
            raise ValueError(f"AODV stats period {self.aodv_stats_period!r}: not a number >= 0")
        _choice(self.aodv_daemon, AODV_DAEMONS, "AODV daemon")

    @property
    def robots(self) -> int:
        return len(self.positions)

    def robot_ids(self) -> range:
        return range(1, self.robots + 1)


def _check_wifi(spec: NetworkSpec) -> None:
    """What the ns3-wifi medium can do: its propagation replaces the range model (the disc,
    for the links the view and the oracle see), and it has no per-link impairments yet."""
    _choice(spec.wifi_loss, WIFI_LOSSES, "wifi loss model")
    _choice(spec.wifi_standard, WIFI_STANDARDS, "wifi standard")
    if not (spec.wifi_rate.isascii() and all(c.isalnum() for c in spec.wifi_rate)):
        raise ValueError(f"wifi rate {spec.wifi_rate!r} is not an ns-3 WifiMode name")
    if spec.range_model != "disc":
        raise ValueError("the ns3-wifi medium decides reception itself: range model disc only")
    if not spec.impairment.is_none:
        raise ValueError("the ns3-wifi medium has no impairments (yet): use the veth medium")


def layout_positions(
    layout: str, robots: int, spacing: float, seed: int | None = None
) -> list[Position]:
    """Positions for `robots` robots: a chain along x, a square-ish grid, or uniform random
    in a square whose side grows with the team so that density stays that of `spacing`."""
    if robots < 1:
        raise ValueError("a testbed needs at least one robot")
    if not (_number(spacing, "spacing") > 0 and math.isfinite(spacing)):
        raise ValueError(f"spacing must be a positive number, not {spacing}")
    if layout == "chain":
        return [(i * spacing, 0.0) for i in range(robots)]
    if layout == "grid":
        cols = math.ceil(math.sqrt(robots))
        return [((i % cols) * spacing, (i // cols) * spacing) for i in range(robots)]
    if layout == "random":
        rng = random.Random(seed)
        side = spacing * math.sqrt(robots)
        return [
            (round(rng.uniform(0, side), 3), round(rng.uniform(0, side), 3)) for _ in range(robots)
        ]
    _choice(layout, LAYOUTS, "layout")
    raise AssertionError(layout)  # every layout is handled above
