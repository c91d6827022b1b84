"""The network timers' arithmetic (topology.kernel.nettimers): division by the time scale, rounding
to the kernel's granularity, its floors and ceilings, and the record of what could not be."""

import math

import pytest

from topology.kernel import nettimers
from topology.kernel.nettimers import BY_NAME, plan

HZ250 = 4000  # a jiffy at HZ = 250 (this project's development kernel), in us
HZ1000 = 1000  # Ubuntu's generic kernels

# A 6.18 kernel's defaults, as a fresh namespace has them (wlan0 the robot's interface).
DEFAULTS_618 = {
    "net.ipv4.tcp_rto_min_us": 200_000,
    "net.ipv4.tcp_rto_max_ms": 120_000,
    "net.ipv4.tcp_comp_sack_delay_ns": 1_000_000,
    "net.ipv4.tcp_comp_sack_slack_ns": 100_000,
    "net.ipv4.tcp_fin_timeout": 60,
    "net.ipv4.tcp_keepalive_time": 7200,
    "net.ipv4.tcp_keepalive_intvl": 75,
    "net.ipv4.tcp_tw_reuse_delay": 1000,
    "net.ipv4.tcp_invalid_ratelimit": 500,
    "net.ipv4.icmp_ratelimit": 1000,
    "net.ipv4.neigh.wlan0.retrans_time_ms": 1000,
    "net.ipv4.neigh.wlan0.base_reachable_time_ms": 30_000,
    "net.ipv4.neigh.wlan0.delay_first_probe_time": 5,
    "net.ipv4.neigh.wlan0.gc_stale_time": 60,
    "net.ipv6.neigh.wlan0.retrans_time_ms": 1000,
    "net.ipv6.neigh.wlan0.base_reachable_time_ms": 30_000,
    "net.ipv6.neigh.wlan0.delay_first_probe_time": 5,
    "net.ipv6.neigh.wlan0.gc_stale_time": 60,
}
# An older kernel (Ubuntu's 6.8): no tcp_rto_min_us (6.11), tcp_rto_max_ms (6.15) nor
# tcp_tw_reuse_delay (6.13).
DEFAULTS_68 = {
    k: v
    for k, v in DEFAULTS_618.items()
    if k.rsplit(".", 1)[1] not in ("tcp_rto_min_us", "tcp_rto_max_ms", "tcp_tw_reuse_delay")
}


def test_every_knob_is_in_the_kernels_defaults_above():
    assert {k.sysctl("wlan0") for k in nettimers.KNOBS} == set(DEFAULTS_618)


def test_time_scale_1_writes_nothing_and_everything_is_the_kernels():
    t = plan(1.0, DEFAULTS_618, HZ250, "6.18")
    assert t.writes() == []
    assert all(s.status == nettimers.DEFAULT and s.value == s.default for s in t.settings)
    assert t.fixed == () and t.not_dilated == [] and t.tcp_dilated


@pytest.mark.parametrize(
    ("scale", "jiffy", "value_us"),
    [
        # (value + 2 jiffies) x K = 200 ms + 2 jiffies, to the nearest jiffy
        (10, HZ250, 12_000),  # (208 / 10 - 8) = 12.8 ms -> 3 jiffies
        (6, HZ250, 28_000),  # 26.7 ms -> 7 jiffies
        (2, HZ250, 96_000),  # 96 ms: 24 jiffies
        (10, HZ1000, 18_000),  # (202 / 10 - 2) = 18.2 ms -> 18 jiffies
        (60, HZ1000, 1_000),  # 1.37 ms -> one jiffy
    ],
)
def test_the_rto_floor_is_divided_with_the_kernels_overhead_on_whole_jiffies(
    scale, jiffy, value_us
):
    knob = BY_NAME["tcp_rto_min"]
    value, emulated = nettimers.dilate(knob, 200_000, scale, jiffy)
    assert value == value_us
    assert value % jiffy == 0
    over = nettimers.RTO_OVERHEAD_JIFFIES * jiffy
    assert emulated == (value + over) * scale - over
    assert abs(emulated - 200_000) <= nettimers.TOLERANCE * 200_000


def test_the_rto_floor_stops_at_one_jiffy_and_says_so():
    t = plan(30, DEFAULTS_618, HZ250, "6.18")
    rto = t.setting("tcp_rto_min")
    assert rto.value == HZ250 and rto.status == nettimers.LIMITED
    assert rto.emulated == (HZ250 + 2 * HZ250) * 30 - 2 * HZ250  # 352 emulated ms
    assert "floor of 4000 us (one jiffy" in rto.note
    assert not t.tcp_dilated and "not dilated at time scale 30" in t.tcp_reason
    # The same scale on a kernel with a 1 ms jiffy keeps it: 5 ms, 3 jiffies of overhead.
    assert plan(30, DEFAULTS_618, HZ1000).tcp_dilated


def test_a_ceiling_under_its_floor_is_clamped_to_the_floor():
    # tcp_rto_max_ms takes nothing under 1000 ms: at K = 200, 600 ms becomes 1000.
    knob = BY_NAME["tcp_rto_max"]
    assert nettimers.dilate(knob, 120_000, 10, HZ250) == (12_000, 120_000)
    value, emulated = nettimers.dilate(knob, 120_000, 200, HZ250)
    assert (value, emulated) == (1000, 200_000)
    s = plan(200, DEFAULTS_618, HZ250).setting("tcp_rto_max")
    assert s.status == nettimers.LIMITED and "floor of 1000 ms" in s.note
    assert "jiffy" not in s.note  # the floor is the kernel's limit, not its granularity


def test_values_kept_in_jiffies_are_rounded_to_the_nearest_jiffy():
    knob = BY_NAME["tcp_invalid_ratelimit"]  # ms, kept in jiffies
    assert nettimers.dilate(knob, 500, 10, HZ250) == (52, 520)  # 50 ms -> 12.5 -> 13 jiffies
    assert nettimers.dilate(knob, 500, 10, HZ1000) == (50, 500)
    neigh = BY_NAME["ipv4_neigh_retrans_time"]
    assert nettimers.dilate(neigh, 1000, 3, HZ250) == (332, 996)  # 333.3 ms -> 83 jiffies


def test_seconds_are_whole_seconds_and_never_zero():
    knob = BY_NAME["ipv4_neigh_delay_first_probe_time"]
    assert nettimers.dilate(knob, 5, 2, HZ250) == (3, 6)  # 2.5 s, halves up
    assert nettimers.dilate(knob, 5, 10, HZ250) == (1, 10)  # 0.5 s: not 0, which disables
    s = plan(10, DEFAULTS_618, HZ250).setting("ipv4_neigh_delay_first_probe_time")
    assert s.status == nettimers.LIMITED and s.emulated == 10
    assert "lasts 10 emulated s instead of 5" in s.note


def test_nanoseconds_are_not_rounded_to_jiffies():
    knob = BY_NAME["tcp_comp_sack_delay"]  # an hrtimer
    assert nettimers.dilate(knob, 1_000_000, 7, HZ250) == (142_857, 999_999)


def test_a_bad_time_scale_or_jiffy_is_refused():
    for scale in (0, -1, math.inf, math.nan):
        with pytest.raises(ValueError):
            plan(scale, DEFAULTS_618, HZ250)
    with pytest.raises(ValueError):
        plan(2, DEFAULTS_618, 0)


def test_a_kernel_without_the_rto_floor_sysctl_records_tcp_as_not_dilated():
    t = plan(6, DEFAULTS_68, HZ1000, "6.8.0-1021-azure")
    rto = t.setting("tcp_rto_min")
    assert rto.status == nettimers.MISSING and rto.value is None
    assert "no net.ipv4.tcp_rto_min_us (Linux 6.11 and later)" in rto.note
    assert not t.tcp_dilated
    assert "tcp_rto_min" in t.not_dilated and "tcp_rto_max" in t.not_dilated
    # What the kernel has is still dilated and written; nothing missing is.
    keys = dict(t.writes())
    assert keys["net.ipv4.neigh.wlan0.retrans_time_ms"] == 167  # 166.7 ms at HZ 1000
    assert "net.ipv4.tcp_rto_min_us" not in keys
    # Without the RTO floor the delayed ACK keeps its 40 ms floor: 240 emulated ms at 6.
    delack = next(f for f in t.fixed if f.name == "tcp_delayed_ack")
    assert (delack.wall_ms, delack.emulated_ms) == (40, 240)


def test_the_compiled_in_timers_are_recorded_with_their_emulated_length():
    t = plan(10, DEFAULTS_618, HZ250)
    fixed = {f.name: f for f in t.fixed}
    assert set(fixed) == {"tcp_syn_rto", "tcp_delayed_ack", "tcp_probe_floor",
                          "tcp_timestamp_clock"}  # fmt: skip
    assert fixed["tcp_syn_rto"].emulated_ms == 10_000
    # The delayed ACK waits at most the RTO floor (3 jiffies) less a jiffy: 8 ms.
    assert fixed["tcp_delayed_ack"].wall_ms == 8 and fixed["tcp_delayed_ack"].emulated_ms == 80
    assert set(fixed) <= set(t.not_dilated)


def test_writes_are_the_dilated_and_limited_settings_only():
    t = plan(10, DEFAULTS_618, HZ250)
    keys = dict(t.writes())
    assert keys["net.ipv4.tcp_rto_min_us"] == 12_000
    assert keys["net.ipv4.tcp_rto_max_ms"] == 12_000
    assert keys["net.ipv6.neigh.wlan0.base_reachable_time_ms"] == 3000
    assert keys["net.ipv4.neigh.wlan0.delay_first_probe_time"] == 1  # limited, still better
    assert len(keys) == len(DEFAULTS_618)


def test_a_refused_value_is_recorded_and_not_written():
    t = nettimers.refused(plan(10, DEFAULTS_618, HZ250), "net.ipv4.tcp_rto_min_us",
                          "Invalid argument")  # fmt: skip
    rto = t.setting("tcp_rto_min")
    assert rto.status == nettimers.REFUSED and "refused 12000 us" in rto.note
    assert "net.ipv4.tcp_rto_min_us" not in dict(t.writes())
    assert not t.tcp_dilated


def test_a_timer_that_is_off_stays_off():
    t = plan(10, {**DEFAULTS_618, "net.ipv4.icmp_ratelimit": 0}, HZ250)
    s = t.setting("icmp_ratelimit")
    assert s.status == nettimers.DEFAULT and s.value == 0
    assert "icmp_ratelimit" not in t.not_dilated


def test_the_per_interface_keys_name_the_robots_interface():
    t = plan(2, {"net.ipv4.neigh.eth1.retrans_time_ms": 1000}, HZ250, dev="eth1")
    assert dict(t.writes()) == {"net.ipv4.neigh.eth1.retrans_time_ms": 500}


def test_the_record_survives_json():
    t = plan(10, DEFAULTS_68, HZ250, "6.8")
    d = t.to_dict()
    assert d["tcp_dilated"] is False
    assert nettimers.NetworkTimers.from_dict(d) == t
    with pytest.raises(ValueError):
        nettimers.NetworkTimers.from_dict({"time_scale": 2})


def test_the_summary_names_what_is_not_dilated():
    line = plan(10, DEFAULTS_618, HZ250).summary()
    assert line.startswith("network timers at time scale 10: 16 dilated")
    assert "TCP's RTO floor 12 ms: 192 emulated" in line and "tcp_syn_rto" in line
    assert plan(1, DEFAULTS_618, HZ250).summary().endswith("the kernel's own")
