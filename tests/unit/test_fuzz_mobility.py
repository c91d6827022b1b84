"""Movement traces from anywhere (topology.inputs.mobility), fuzzed with Hypothesis: every input
ends in exactly one of two ways. Either the trace is accepted and sane (at most 1000 nodes,
its end and every sampled position finite and within the limits, its ticks generated
lazily), or it is refused with a `TraceError` of one printable line. Nothing else: no other
exception, no hang (each example has a deadline), no allocation the limits do not allow.

Inputs are of three kinds: lines built from the two formats' grammar with hostile numbers
in every field (ids of 1e15, times of 1e12, speeds of 1e-320, nan, inf, overlong digit
strings), arbitrary text, mutations of a valid trace, and traces of plausible numbers only (mostly
accepted: the sane side of the property): 1250 examples in all.
"""

import math

from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from topology.inputs import mobility

BASE = settings(deadline=2000, suppress_health_check=[HealthCheck.too_slow], database=None)

PLAUSIBLE = st.one_of(
    st.integers(0, 100).map(str),
    st.floats(0, 100, allow_nan=False).map(repr),
)
HOSTILE = st.one_of(
    st.integers(-5, 1200).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(
        [
            "1e15",
            "1e11",
            "1e12",
            "1e-320",
            "-0",
            "1e6",
            "1000000.0000001",
            "999",
            "1000",
            "nan",
            "inf",
            "-inf",
            "1" * 400,
            "0." + "0" * 300 + "1",
            ".5",
            "5.",
            "+3",
            "1e",
            "0x10",
            "",
        ]
    ),  # fmt: skip
)
NUMBERS = st.one_of(*[PLAUSIBLE] * 7, HOSTILE)
IDS = st.one_of(
    st.integers(0, 3).map(str),
    st.integers(0, 3).map(str),
    st.integers(0, 1100).map(str),
    st.sampled_from(["100000000000", "1" * 50, "1e15", "2.5"]),
)


@st.composite
def ns2_traces(draw, numbers=NUMBERS, ids=IDS, odd_lines=True) -> str:
    """A trace built as BonnMotion writes one (each node's X_ and Y_, then legs), with a
    hostile number, id or line wherever the draw puts one."""
    nodes = draw(st.integers(1, 4))
    lines = []
    for i in range(nodes):
        for axis in "XY":
            lines.append(f"$node_({i}) set {axis}_ {draw(numbers)}")
    for _ in range(draw(st.integers(0, 6))):
        ns = draw(st.sampled_from(["$ns_", "$ns"]))
        node = draw(st.one_of(st.integers(0, nodes - 1).map(str), ids))
        t, x, y, v = (draw(numbers) for _ in range(4))
        lines.append(f'{ns} at {t} "$node_({node}) setdest {x} {y} {v}"')
    if odd_lines and draw(st.integers(0, 5)) == 0:
        at = draw(st.integers(0, len(lines)))
        lines.insert(at, draw(st.sampled_from(["# note", "", "$node_(0) set Z_ 0",
                                               f"$node_({draw(IDS)}) set X_ 1"])))  # fmt: skip
    return "\n".join(lines)


@st.composite
def one_traces(draw, numbers=NUMBERS, ids=IDS, odd_lines=True) -> str:
    """A ONE trace: maybe a header, then `time id x y` samples of nodes 0..k-1, with a
    hostile field or a line of another width wherever the draw puts one."""
    nodes = draw(st.integers(1, 4))
    lines = []
    if draw(st.booleans()):
        width = draw(st.sampled_from([6, 6, 8]))
        bounds = draw(st.sampled_from([["0", "1e6", "-1e6", "1e6", "-1e6", "1e6"],
                                       ["0", "100", "0", "100", "0", "100"]]))  # fmt: skip
        lines.append(" ".join(bounds + ["0", "0"][: width - 6]))
    for i in list(range(nodes)) + [None] * draw(st.integers(0, 6)):
        node = str(i) if i is not None else draw(ids)
        t, x, y = (draw(numbers) for _ in range(3))
        lines.append(f"{t} {node} {x} {y}")
    if odd_lines and draw(st.integers(0, 5)) == 0:
        width = draw(st.sampled_from([3, 5, 6, 9]))
        lines.insert(draw(st.integers(0, len(lines))), " ".join(["1"] * width))
    return "\n".join(lines)


def check(text: str) -> None:
    """The property: accepted and sane, or one line of refusal."""
    try:
        tr = mobility.parse(text, "fuzz")
    except mobility.TraceError as exc:
        msg = str(exc)
        assert msg.startswith("fuzz") and msg.isprintable(), msg
        event("refused")
        return
    event("accepted")
    assert 1 <= tr.nodes <= mobility.MAX_NODE_ID + 1
    end = tr.end
    assert math.isfinite(end) and 0 <= end <= mobility.MAX_TIME_S
    for t in (0.0, end / 3, end / 2, end, end + 1.0):
        for x, y in tr.positions(t):
            assert math.isfinite(x) and math.isfinite(y)
            assert abs(x) <= mobility.MAX_COORD_M and abs(y) <= mobility.MAX_COORD_M
    for m in tr.motions:
        assert m.times == sorted(m.times) and len(m.times) == len(m.points)
    ticks = mobility.ticks(end, 0.1)
    first = [next(ticks) for _ in range(2)] if end > 0.1 else list(ticks)
    assert first[0] == 0.0


@settings(BASE, max_examples=300)
@given(ns2_traces())
def test_ns2_traces(text):
    check(text)


@settings(BASE, max_examples=150)
@given(st.one_of(ns2_traces(PLAUSIBLE, st.just("0"), False),
                 one_traces(PLAUSIBLE, st.just("0"), False)))  # fmt: skip
def test_plausible_traces_are_mostly_accepted_and_sane(text):
    check(text)


@settings(BASE, max_examples=300)
@given(one_traces())
def test_one_traces(text):
    check(text)


@settings(BASE, max_examples=250)
@given(st.text(max_size=400))
def test_arbitrary_text(text):
    check(text)


VALID = """\
$node_(0) set X_ 0.0
$node_(0) set Y_ 0.0
$node_(1) set X_ 10.0
$node_(1) set Y_ 0.0
$ns_ at 1.0 "$node_(0) setdest 3.0 4.0 5.0"
$ns_ at 2.0 "$node_(1) setdest 10.0 10.0 1.0"
"""


@settings(BASE, max_examples=250)
@given(st.data())
def test_mutated_valid_traces(data):
    text = VALID
    for _ in range(data.draw(st.integers(1, 4))):
        at = data.draw(st.integers(0, len(text)))
        cut = data.draw(st.integers(0, 5))
        text = text[:at] + data.draw(st.text(max_size=12)) + text[at + cut :]
    check(text)
