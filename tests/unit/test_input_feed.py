"""The feed's input: lines cut anywhere, a last line without newline, a line without end,
coordinates that are not finite or absurdly far."""

import time

import pytest

from topology.inputs import feed
from topology.inputs.linebuffer import TOO_LONG, LineBuffer


def lines_of(chunks: list[bytes], limit: int = 64) -> list[bytes | None]:
    buf = LineBuffer(limit)
    out = []
    for c in chunks:
        out += buf.feed(c)
    return out + buf.end()


def test_a_last_line_without_newline_is_exactly_that_line():
    assert lines_of([b"1 5"]) == [b"1 5"]
    assert lines_of([b"2 12 0"]) == [b"2 12 0"]
    assert lines_of([b"1 0 0\n", b"2 1", b"2 0"]) == [b"1 0 0", b"2 12 0"]
    assert lines_of([b"1 0 0\n"]) == [b"1 0 0"]  # no empty line after the last newline
    assert lines_of([b""]) == []
    # Cut anywhere, the same lines.
    text = b"1 0 0\n\n# c\n2 5 5\n3 1"
    for cut in range(len(text) + 1):
        assert lines_of([text[:cut], text[cut:]]) == [b"1 0 0", b"", b"# c", b"2 5 5", b"3 1"]


def test_a_line_over_the_limit_is_given_once_and_the_next_lines_follow():
    assert lines_of([b"x" * 65 + b"\n1 0 0\n"]) == [TOO_LONG, b"1 0 0"]
    assert lines_of([b"x" * 64 + b"\n"]) == [b"x" * 64]
    assert lines_of([b"x" * 40, b"x" * 40, b"x" * 40, b"\n2 0 0"]) == [TOO_LONG, b"2 0 0"]
    assert lines_of([b"x" * 100]) == [TOO_LONG]  # unterminated and too long: once


def test_a_100_mb_line_costs_time_linear_in_its_length():
    buf = LineBuffer(feed.MAX_LINE_BYTES)
    chunk = b"7" * (1 << 16)
    out = []
    t0 = time.process_time()
    for _ in range(100 * (1 << 20) // len(chunk)):  # 100 MiB in the feed's read size
        out += buf.feed(chunk)
    out += buf.feed(b"\n1 2 3\n") + buf.end()
    assert time.process_time() - t0 < 2.0  # joining the buffer to every chunk took 73 s
    assert out == [TOO_LONG, b"1 2 3"]


@pytest.mark.parametrize(
    "line, message",
    [
        ("1 -1e308 1e308", "beyond 10,000,000 m"),
        ("1 nan 0", "finite"),
        ("1 0 inf", "finite"),
        ("r1 1e7 1.0000001e7", "beyond"),
        ("1e7 1 0 0", "time"),
        ("inf 1 0 0", "time"),
        ("-1 1 0 0", "time"),
        ("r² 0 0", "K or rK"),
        ("1 5", "2 fields"),
        ("1 a b", "not two numbers"),
    ],
)
def test_lines_that_are_not_finite_or_absurd_are_refused(line, message):
    with pytest.raises(ValueError, match=message):
        feed.parse_line(line)


def test_lines_at_the_limits_are_accepted():
    assert feed.parse_line("r1000 -1e7 1e7") == (None, 1000, -1e7, 1e7)
    assert feed.parse_line(f"{feed.MAX_TIME_S} 3 0.5 0") == (feed.MAX_TIME_S, 3, 0.5, 0.0)
