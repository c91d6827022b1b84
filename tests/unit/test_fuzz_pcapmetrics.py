"""The metrics' reading of captures (testbed.analysis.pcapmetrics), fuzzed with Hypothesis.

The captures themselves are read by tshark; what is ours is the parser of tshark's
tab-separated output (`parse_fields`) and the arithmetic on what it parsed (`compute`). A
capture from elsewhere (a results directory from someone else) reaches both. The property:
every line is either a frame whose fields are within what tshark can write, or skipped;
and the metrics of any parsed frames are finite numbers (or None where undefined), counts
are whole and not negative, never NaN or an overflow. 600 examples in all.
"""

import math

from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from testbed.analysis import pcapmetrics
from testbed.analysis.pcapmetrics import _FIELDS, compute, parse_fields
from testbed.analysis.pcapread import MAX_TIME_S

BASE = settings(deadline=2000, suppress_health_check=[HealthCheck.too_slow], database=None)

ADDRS = {1: "10.0.0.1", 2: "10.0.0.2", 3: "10.0.0.3"}
HOSTILE = st.one_of(
    st.sampled_from(
        [
            "",
            "nan",
            "inf",
            "-1",
            "-0",
            "1e308",
            "9" * 30,
            "9" * 5000,
            "0x10",
            "65536",
            "4294967296",
            "1.5",
            " 7",
            "\x00",
            "6,17",
        ]
    ),  # fmt: skip
    st.text(max_size=6),
    st.integers().map(str),
)


def _line(mac_src, mac_dst, ip_src, ip_dst, proto, *, udp=("", ""), tcp=("", ""), seq="",
          tcp_len="", aodv="", ttl="64", length="100") -> list[str]:  # fmt: skip
    f = dict.fromkeys(_FIELDS, "")
    f.update({"frame.len": length, "eth.src": mac_src, "eth.dst": mac_dst, "ip.src": ip_src,
              "ip.dst": ip_dst, "ip.proto": proto, "ip.ttl": ttl, "udp.srcport": udp[0],
              "udp.dstport": udp[1], "udp.length": "32" if udp[0] else "",
              "tcp.srcport": tcp[0], "tcp.dstport": tcp[1], "tcp.seq_raw": seq,
              "tcp.len": tcp_len, "aodv.type": aodv, "frame.interface_id": "0"})  # fmt: skip
    return [f[name] for name in _FIELDS]


M1, M2, BCAST = "02:00:00:00:00:01", "02:00:00:00:00:02", "ff:ff:ff:ff:ff:ff"
A1, A2 = "10.0.0.1", "10.0.0.2"
# What tshark writes for a run's traffic (time first, filled in per line): a TCP segment
# from r1 to r2, its ACK, AODV's RREQ and HELLO, a stray ICMP message.
TEMPLATES = [
    _line(M1, M2, A1, A2, "6", tcp=("40000", "5555"), seq="1000", tcp_len="1448"),
    _line(M2, M1, A2, A1, "6", tcp=("5555", "40000"), seq="77", tcp_len="0"),
    _line(M1, BCAST, A1, "255.255.255.255", "17", udp=("654", "654"), aodv="1"),
    _line(M2, BCAST, A2, "255.255.255.255", "17", udp=("654", "654"), aodv="2", ttl="1"),
    _line(M1, M2, A1, A2, "1"),
]


@st.composite
def tshark_lines(draw) -> str:
    """A template line at a time of its own, with a field or two made hostile now and then,
    or cut short."""
    fields = [draw(st.floats(1.7e9, 1.7e9 + 100).map(repr)), *draw(st.sampled_from(TEMPLATES))[1:]]
    for _ in range(draw(st.sampled_from([0, 0, 0, 1, 2]))):
        fields[draw(st.integers(0, len(fields) - 1))] = draw(HOSTILE)
    return "\t".join(fields[: draw(st.sampled_from([len(fields)] * 6 + [3, 1]))])


def numbers(value):
    """Every number in a metrics dict, nested."""
    if isinstance(value, dict):
        for v in value.values():
            yield from numbers(v)
    elif isinstance(value, list | tuple):
        for v in value:
            yield from numbers(v)
    elif isinstance(value, int | float) and not isinstance(value, bool):
        yield value


def check(captures_text: dict[int, str]) -> None:
    captures = {}
    for k, text in captures_text.items():
        frames = parse_fields(text)
        assert len(frames) <= len(text.splitlines())
        for f in frames:
            assert 0 <= f.time <= MAX_TIME_S and 0 <= f.length <= 0xFFFFFFFF
            for port in (f.udp_sport, f.udp_dport, f.tcp_sport, f.tcp_dport):
                assert port is None or 0 <= port <= 0xFFFF
        captures[k] = frames
    event(f"{sum(len(f) for f in captures.values()) // 10 * 10}+ frames parsed")
    m = compute(captures, {k: ADDRS[k] for k in captures})
    for x in numbers(m):
        assert math.isfinite(x), m
    for key in ("tx_packets", "control_tx_packets", "tcp_segments_sent", "tcp_transmissions"):
        assert isinstance(m[key], int) and m[key] >= 0
    for key in ("pdf", "segment_delivery", "overhead_packets", "overhead_bytes"):
        assert m[key] is None or m[key] >= 0


@settings(BASE, max_examples=350)
@given(st.dictionaries(st.sampled_from([1, 2, 3]),
                       st.lists(tshark_lines(), max_size=10).map("\n".join),
                       min_size=1))  # fmt: skip
def test_tshark_output_of_any_shape(captures_text):
    check(captures_text)


@settings(BASE, max_examples=250)
@given(st.text(max_size=300))
def test_arbitrary_text_as_tshark_output(text):
    check({1: text})


def test_a_line_out_of_its_fields_range_is_skipped_not_counted():
    good = "\t".join(["1.5", "100", M1, M2, A1, A2, "6"] + [""] * 11)
    assert len(parse_fields(good)) == 1
    for bad in ("nan", "inf", "-1"):
        assert parse_fields(good.replace("1.5", bad, 1)) == []
    assert parse_fields(good.replace("\t100\t", "\t-100\t", 1)) == []
    assert parse_fields(good.replace("\t100\t", "\t" + "9" * 5000 + "\t", 1)) == []
    assert pcapmetrics._int("65535") == 65535 and pcapmetrics._int("") is None


def test_a_time_past_any_capture_is_skipped():
    """Found by the fuzzer: a frame stamped 1e308 s made the run last 1e308 s, and a delay in
    milliseconds of it infinite. Such a line is not what tshark writes: it is skipped."""
    row = "\t100\t02:00:00:00:00:01\t02:00:00:00:00:02\t10.0.0.1\t10.0.0.2\t6\t64\t\t\t\t40000"
    row += "\t5555\t1000\t1448\t\t\t0\t\t"
    assert parse_fields("1e308" + row) == []
    assert len(parse_fields("1700000000.0" + row)) == 1
    m = compute({1: parse_fields("1700000000.0" + row), 2: parse_fields("1e308" + row)},
                {1: ADDRS[1], 2: ADDRS[2]})  # fmt: skip
    assert all(math.isfinite(x) for x in numbers(m)) and m["duration_s"] == 0.0
