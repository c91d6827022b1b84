"""Results directories to attack: a small finished sweep and a finished run, made the way
the testbed writes them (tests.unit.test_sweep_synthetic), and the one way every hostile
case is judged: `testbed ...` run in this process, which must either succeed or print
exactly one line and exit 2, never a traceback, and never write outside the directory."""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

from testbed import cli
from testbed.sweep import file as sweepfile
from tests.unit.test_sweep_synthetic import make_sweep, result_doc, write_run


def sweep_dir(out: Path) -> Path:
    """A finished sweep of teams of 1 and 2 robots, two runs each."""
    spec = sweepfile.SweepSpec.of(robots=(1, 2), comm_range=(5.0,), laser_range=(2.0,), runs=2)
    make_sweep(out, spec)
    return out


def run_dir(out: Path) -> Path:
    """One finished run of 2 robots (in out/runs/ID), no captures."""
    spec = sweepfile.SweepSpec.of(robots=(2,), comm_range=(5.0,), laser_range=(2.0,), runs=1)
    run = sweepfile.expand(spec)[0]
    doc = result_doc(dataclasses.replace(run.config, time_scale=1.0), [817, 823], 823)
    return write_run(out, run, doc)


# A capture with no packets: pcap's global header (little-endian, version 2.4, Ethernet).
EMPTY_PCAP = bytes.fromhex("d4c3b2a1020004000000000000000000ffff000001000000")


def edit_result(run: Path, change) -> None:
    """Rewrite run/result.json with change(doc) applied (change edits doc in place)."""
    doc = json.loads((run / "result.json").read_text())
    change(doc)
    (run / "result.json").write_text(json.dumps(doc))


def testbed(argv: list[str], capsys) -> tuple[int, str, str]:
    """(exit status, stdout, stderr) of `testbed ARGV` in this process; a traceback
    (an exception the CLI does not turn into one line) fails the calling test."""
    status = cli.main([str(a) for a in argv])
    got = capsys.readouterr()
    return status, got.out, got.err


def refused(argv: list[str], capsys, *words: str) -> str:
    """Asserts that `testbed ARGV` is one line on stderr and exit 2, the line holding every
    one of `words`; returns the line."""
    status, _, err = testbed(argv, capsys)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert status == 2, err
    assert len(lines) == 1, err
    for w in words:
        assert w in lines[0], lines[0]
    return lines[0]


def snapshot(d: Path) -> dict[str, bytes]:
    """Every regular file below d (links not followed) and its content."""
    out = {}
    for root, _, files in os.walk(d):
        for f in files:
            p = Path(root) / f
            if p.is_file() and not p.is_symlink():
                out[str(p.relative_to(d))] = p.read_bytes()
    return out


def png_bytes(marker: bytes = b"") -> bytes:
    """A PNG's signature and a 1x1 header, then `marker` (enough for the PNG checks)."""
    ihdr = (13).to_bytes(4, "big") + b"IHDR" + (1).to_bytes(4, "big") * 2
    return b"\x89PNG\r\n\x1a\n" + ihdr + marker


class Hung(Exception):
    """The command under test did not return in time (it waited on a FIFO)."""


def within(seconds: int, fn, *args):
    """fn(*args), or Hung if it takes longer than `seconds` (SIGALRM interrupts a blocked
    open() or read() of a FIFO, so a hang fails the test instead of stopping the suite)."""
    import signal

    def ring(signum, frame):
        raise Hung(f"no answer in {seconds} s")

    old = signal.signal(signal.SIGALRM, ring)
    signal.alarm(seconds)
    try:
        return fn(*args)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def fifo(path: Path) -> Path:
    """A FIFO at `path` (whatever was there removed first): nobody will ever write to it."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.exists() or path.is_symlink():
        path.unlink()
    os.mkfifo(path)
    return path


def with_captures(run: Path, robots=(1, 2)) -> Path:
    """Give run empty captures (headers only), a tcpdump log each and AODV counters."""
    (run / "pcaps" / "daemons").mkdir(parents=True, exist_ok=True)
    (run / "aodv").mkdir(exist_ok=True)
    for k in robots:
        (run / "pcaps" / f"r{k}.pcap").write_bytes(EMPTY_PCAP)
        (run / "pcaps" / "daemons" / f"r{k}.tcpdump.log").write_text(
            "0 packets dropped by kernel\n"
        )
        (run / "aodv" / f"r{k}.json").write_text(json.dumps({"messages_sent": {"RREQ": 1}}))
    return run


def udp_pcap(src_k: int, frames: int, port: int = 5000) -> bytes:
    """A capture of `frames` UDP datagrams from robot src_k (10.0.0.K) to 10.0.0.250, one
    a millisecond: enough for tshark to read and tell one capture's frames from another's."""
    import struct

    out = [EMPTY_PCAP]
    for i in range(frames):
        payload = b"x" * 16
        udp = struct.pack("!HHHH", port, port, 8 + len(payload), 0) + payload
        ip = struct.pack("!BBHHHBBH4s4s", 0x45, 0, 20 + len(udp), i, 0, 64, 17, 0,
                         bytes([10, 0, 0, src_k]), bytes([10, 0, 0, 250]))  # fmt: skip
        eth = bytes([2, 0, 0, 0, 0, 250, 2, 0, 0, 0, 0, src_k]) + b"\x08\x00"
        frame = eth + ip + udp
        out.append(struct.pack("<IIII", 1000, 1000 * i, len(frame), len(frame)) + frame)
    return b"".join(out)
