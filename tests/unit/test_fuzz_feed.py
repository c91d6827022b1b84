"""Property tests of the feed's input (Hypothesis): whatever a line holds and however a
stream is cut, exactly one of two outcomes: accepted and sane (a robot in range, finite
coordinates within MAX_COORD_M, a time within MAX_TIME_S; lines no longer than the limit),
or refused with one line saying why."""

import math

from hypothesis import given, settings
from hypothesis import strategies as st

from topology.inputs import feed
from topology.inputs.linebuffer import TOO_LONG, LineBuffer
from topology.names import MAX_ROBOTS
from topology.spec import MAX_COORD_M

FUZZ = dict(deadline=None, database=None)

# Tokens near the edges: numbers of every spelling, robots in and out of range, junk.
NUMBERS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.floats(-2 * MAX_COORD_M, 2 * MAX_COORD_M).map(str),
    st.integers(-(10**30), 10**30).map(str),
    st.sampled_from(
        [
            "nan",
            "-inf",
            "Infinity",
            "1e308",
            "-1e309",
            "1_0",
            "0x10",
            "1e",
            ".",
            "+.5",
            "١",
            "²",
            "",
            "   ",
        ]
    ),  # fmt: skip
)
ROBOTS = st.one_of(
    st.integers(-5, MAX_ROBOTS + 5).map(str),
    st.integers(0, MAX_ROBOTS + 5).map(lambda k: f"r{k}"),
    st.sampled_from(["r", "R3", "r²", "٣", "1.0", "r1\n", "99999999999999999999"]),
)
LINES = st.one_of(
    st.text(max_size=80),
    st.tuples(ROBOTS, NUMBERS, NUMBERS).map(" ".join),
    st.tuples(NUMBERS, ROBOTS, NUMBERS, NUMBERS).map(" ".join),
    st.lists(st.one_of(NUMBERS, ROBOTS), max_size=6).map(" ".join),
)


def check_line(line: str) -> None:
    try:
        parsed = feed.parse_line(line)
    except ValueError as e:
        message = str(e)
        assert message and "\n" not in message and len(message) < 300, repr(message)
        return
    if parsed is None:
        assert not line.strip() or line.strip().startswith("#")
        return
    t, k, x, y = parsed
    assert t is None or (math.isfinite(t) and 0 <= t <= feed.MAX_TIME_S)
    assert type(k) is int and 1 <= k <= MAX_ROBOTS
    for v in (x, y):
        assert type(v) is float and math.isfinite(v) and abs(v) <= MAX_COORD_M


@settings(max_examples=1000, **FUZZ)
@given(LINES)
def test_a_feed_line_is_either_sane_or_refused_in_one_line(line):
    check_line(line)


@settings(max_examples=300, **FUZZ)
@given(st.binary(max_size=200))
def test_any_bytes_decode_to_a_line_that_is_sane_or_refused(raw):
    check_line(raw.decode(errors="replace"))


def reference(data: bytes, limit: int, eof: bool) -> list:
    """The lines of `data` as a plain split gives them, too long ones as TOO_LONG."""
    *whole, last = data.split(b"\n")
    out = [TOO_LONG if len(line) > limit else line for line in whole]
    if len(last) > limit:
        out.append(TOO_LONG)  # reported as soon as seen, with or without its end
    elif eof and last:
        out.append(last)
    return out


@settings(max_examples=500, **FUZZ)
@given(
    st.lists(st.binary(max_size=40).map(lambda b: b.replace(b"\r", b"\n")), max_size=12),
    st.integers(1, 24),
)
def test_lines_come_out_whole_bounded_and_the_same_however_the_stream_is_cut(chunks, limit):
    buf = LineBuffer(limit)
    out = []
    for chunk in chunks:
        out += buf.feed(chunk)
        assert len(buf._part) <= limit  # memory is bounded by the limit, whatever comes
    assert out == reference(b"".join(chunks), limit, eof=False)
    out += buf.end()
    assert out == reference(b"".join(chunks), limit, eof=True)
    assert all(line is TOO_LONG or len(line) <= limit for line in out)
