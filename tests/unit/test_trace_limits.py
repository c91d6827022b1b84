"""What a movement trace may ask for (topology.inputs.mobility's limits) and the player that plays
it (topology.inputs.player): hostile traces are refused while parsing, in one line, before anything
is allocated for them. No root.

The traces that used to eat the machine are parsed in a child process with its address space
capped at 1 GB and a time limit, so that code without the limits fails the test (MemoryError,
or killed at the time limit) instead of taking the test machine down with it.
"""

import os
import re
import resource
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from common.errors import UsageError
from testbed.cli import build_parser
from topology.inputs import mobility, player

REPO = Path(__file__).resolve().parents[2]
ADDRESS_SPACE = 1 << 30


def _capped():  # runs in the child between fork and exec
    resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE, ADDRESS_SPACE))


def load_capped(path: str, timeout: float = 20.0) -> str:
    """`mobility.load(path)` in a child capped at 1 GB: its TraceError message, or what else
    happened to it (a traceback's last line, or 'timeout')."""
    code = textwrap.dedent(f"""
        from topology.inputs import mobility
        try:
            tr = mobility.load({path!r})
            print("accepted", tr.nodes, tr.end)
        except mobility.TraceError as exc:
            print("refused", exc)
    """)
    try:
        r = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True,
                           text=True, timeout=timeout, preexec_fn=_capped)  # fmt: skip
    except subprocess.TimeoutExpired:
        return "timeout"
    return (r.stdout.strip() or r.stderr.strip().splitlines()[-1]).strip()


def ns2(*legs: str, nodes: int = 1) -> str:
    head = "".join(f"$node_({i}) set X_ {i}\n$node_({i}) set Y_ 0\n" for i in range(nodes))
    return head + "".join(leg + "\n" for leg in legs)


@pytest.mark.parametrize(
    "text, refused",
    [
        ("$node_(100000000000) set X_ 1\n$node_(100000000000) set Y_ 1\n",
         "line 1: node id 100000000000 is not a whole number 0..999"),
        (ns2('$ns_ at 1 "$node_(99999999999) setdest 1 1 1"'), "line 3: node id 99999999999"),
        ("0 1000000000000000 0 0\n", "line 1: node id 1000000000000000 is not a whole number"),
        ("0 1e15 0 0\n", "line 1: node id 1e15"),
        ("0 1000 0 0\n", "node id 1000 is not a whole number 0..999"),
        ("0 2.5 0 0\n", "node id 2.5 is not a whole number"),
    ],
)  # fmt: skip
def test_node_ids_beyond_a_testbeds_robots_are_refused_before_any_allocation(
    tmp_path, text, refused
):
    f = tmp_path / "trace"
    f.write_text(text)
    outcome = load_capped(str(f))
    assert outcome.startswith(f"refused {f}: ") and refused in outcome, outcome


@pytest.mark.parametrize(
    "leg, refused",
    [
        ('$ns_ at 1e12 "$node_(0) setdest 1 1 1"', "line 3: time 1e12 is past the limit of 1e6 s"),
        ('$ns_ at 1 "$node_(0) setdest 10 0 1e-320"',
         "line 3: node 0 would arrive at inf s (10 m at 1e-320 m/s), past the limit of 1e6 s"),
        ('$ns_ at 1 "$node_(0) setdest 1e7 0 1"', "line 3: x 1e7 is beyond +-1e6 m"),
        ('$ns_ at 999999 "$node_(0) setdest 100 0 1"', "line 3: node 0 would arrive at"),
    ],
)  # fmt: skip
def test_times_and_arrivals_past_the_limit_are_refused_at_parse_time(leg, refused):
    with pytest.raises(mobility.TraceError, match=re.escape(refused)):
        mobility.parse(ns2(leg), "f")


def test_one_times_and_coordinates_past_the_limits_are_refused():
    with pytest.raises(mobility.TraceError, match="line 1: time 2e6 is past the limit"):
        mobility.parse("2e6 0 0 0\n", "f")
    with pytest.raises(mobility.TraceError, match=r"line 2: y -5e6 is beyond \+-1e6 m"):
        mobility.parse("0 0 0 0\n1 0 0 -5e6\n", "f")


def test_the_limits_as_stated_are_the_limits_as_checked():
    assert float(mobility._TIME_TEXT.split()[0]) == mobility.MAX_TIME_S
    assert float(mobility._COORD_TEXT.split()[0]) == mobility.MAX_COORD_M
    assert mobility.MAX_NODE_ID == 999
    # the largest of each is accepted
    text = "".join(f"0 {i} 0 0\n" for i in range(1000)) + "1000000 999 1e6 -1e6\n"
    tr = mobility.parse(text, "f")
    assert tr.nodes == 1000 and tr.end == 1e6 and tr.positions(1e6)[999] == (1e6, -1e6)


def test_largest_accepted_trace_is_finite_everywhere():
    """Extreme but legal values interpolate to finite positions (no inf - inf)."""
    tr = mobility.parse("0 0 -1e6 -1e6\n1e6 0 1e6 1e6\n", "f")
    for t in (0.0, 0.5, 5e5, 1e6 - 1e-3, 1e6, 2e6):
        x, y = tr.positions(t)[0]
        assert abs(x) <= 1e6 and abs(y) <= 1e6


def test_dev_zero_fifo_and_directories_are_refused_without_reading(tmp_path):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)  # nobody writes to it: opening it for reading would block forever
    assert load_capped("/dev/zero") == "refused /dev/zero: not a regular file (a trace is " \
        "read from a file, not a pipe or a device)"  # fmt: skip
    assert load_capped(str(fifo), timeout=10) == (
        f"refused {fifo}: not a regular file (a trace is read from a file, not a pipe or a device)"
    )
    with pytest.raises(mobility.TraceError, match="is a directory"):
        mobility.load(str(tmp_path))


def test_a_file_over_the_size_limit_is_refused_before_it_is_read(tmp_path):
    big = tmp_path / "big"
    with open(big, "wb") as f:  # sparse: no disk used
        f.truncate(mobility.MAX_FILE_BYTES + 1)
    with pytest.raises(mobility.TraceError, match="over the limit of 64 MiB"):
        mobility.load(str(big))


def test_one_long_line_is_refused_by_its_length(tmp_path):
    f = tmp_path / "long"
    f.write_text("0 0 0 0\n" + "1 " * 10_000_000 + "\n")  # one 20 MB line
    assert load_capped(str(f)) == (
        f"refused {f}: line 2: 20000000 characters long; a trace line has at most 1000"
    )


def test_ticks_are_generated_one_at_a_time():
    code = textwrap.dedent("""
        from topology.inputs import mobility
        it = mobility.ticks(1e6, 1e-3)  # 1e9 ticks: 8 GB as a list
        print(next(iter(it)), next(iter(it)))
    """)
    r = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True,
                       timeout=30, preexec_fn=_capped)  # fmt: skip
    assert r.stdout.split() == ["0.0", "0.001"], r.stderr[-300:]


def test_a_tick_below_the_limit_is_refused_by_net_up_and_the_player():
    with pytest.raises(UsageError, match="tick must be at least 0.001"):
        build_parser(["net"]).parse_args(["net", "up", "x", "--mobility", "f", "--tick", "1e-9"])
    with pytest.raises(SystemExit) as exc:
        player.main(["x", "f", "--links-out", "/dev/null", "--tick", "1e-9"])
    assert exc.value.code == 2
    with pytest.raises(ValueError):
        next(iter(mobility.ticks(10.0, 1e-9)))


def test_net_up_help_states_the_trace_limits(capsys):
    with pytest.raises(SystemExit):
        build_parser(["net"]).parse_args(["net", "up", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "node ids 0..999" in text and "up to 1e6 s" in text and "64 MiB" in text
    assert "at least 0.001" in text


@pytest.mark.parametrize(
    "text, refused",
    [
        # the first line has 6 fields, but its "bounds" contradict the records: not a header
        ("0 1 2 3 4 5\n0 0 0 0\n", "line 2: x 0 is outside the header's 2..3"),
        ("0 100 0 100 0 100\n5 0 200 0\n", "line 2: x 200 is outside the header's 0..100"),
        ("0 100 0 100 0 100\n500 0 1 1\n", "line 2: time 500 is outside the header's 0..100"),
        ("5 1 0 100 0 100\n1 0 1 1\n", "line 1: ONE header: minTime 5 is above maxTime 1"),
        ("0 100 0 x 0 100\n1 0 1 1\n", "line 1: a first line of 6 or 8 fields is the ONE header"),
        ("0 0 0 0\n0 100 0 100 0 100\n", "line 2: expected 4 fields 'time id x y', found 6"),
    ],
)  # fmt: skip
def test_a_one_header_is_checked_not_skipped(text, refused):
    with pytest.raises(mobility.TraceError, match=refused):
        mobility.parse(text, "f")


def test_a_real_one_header_is_read_as_one():
    tr = mobility.parse("0 10 0 50 0 50 0 0\n0 0 1 1\n10 0 2 2\n", "f")
    assert tr.nodes == 1 and tr.end == 10.0
    tr = mobility.parse("0 0 1 1\n10 0 2 2\n", "f")  # ONE without its header: still read
    assert tr.positions(5.0) == [(1.5, 1.5)]


def test_a_player_that_cannot_start_says_why_in_one_line(tmp_path, caplog):
    f = tmp_path / "t.one"
    f.write_text("0 0 0 0\n")
    assert player.main(["nosuchtb", str(f), "--links-out", str(tmp_path / "l.csv")]) == 2
    errors = [r.getMessage() for r in caplog.records if r.levelname == "ERROR"]
    assert errors == ["error: no testbed named 'nosuchtb' is up"]
