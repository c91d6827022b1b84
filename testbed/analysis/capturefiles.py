"""The files of a run's captures as testbed.analysis.pcapmetrics takes them, none trusted:
which captures may be read, the AODV daemons' counters (aodv/rK.json), tcpdump's last words
(pcaps/daemons/rK.tcpdump.log), and the content hash routing.json's cache is keyed on.

Theory of operation. A results directory may come from elsewhere, so:

- a capture is `pcaps/rK.pcap` (or .pcapng) with K a robot (1..MAX_ROBOTS, plain digits), a
  regular file inside the run directory (no FIFO, no link out of it) of at most
  MAX_CAPTURE_BYTES that starts with a pcap or pcapng header. Any other is left out and
  named (`Captures.left_out`), so no robot's frames are credited to another (mergecap skips
  an empty file, which shifts every later capture's interface id onto the wrong robot);
- before tshark reads them (`checked`, when routing.json's cache does not answer), each
  capture's records are walked: a record claiming more than MAX_RECORD_BYTES (a length of
  2^32-1), a pcapng block that is not one, or more than MAX_CAPTURE_FRAMES frames (a sparse
  file of empty records) leaves it out, named; so do two captures or more that are one
  file (a hard link: the same device and inode) or the same bytes (a copy), every one of
  them, since whose frames they are cannot be told (read as two robots', a copy made a
  delivery of 1.06 and delays of 0 ms). A last record cut short (a run killed mid-write) is
  not a fault: what comes before it is read;
- the daemons' counters are read through their type (aodv.statsfile), tcpdump's logs
  through the one bounded reader (common.boundedfile): a FIFO is refused, not waited on; a
  count that is not a whole number from 0 to its MAX_COUNT leaves that robot's counters
  out, said so;
- the routing-metrics cache is keyed on a SHA-256 of every capture's (and the relay-lag
  file's) content, which a tarball cannot carry over from other captures as it does mtimes.
"""

from __future__ import annotations

import hashlib
import logging
import os
import re
import struct
from collections import Counter, defaultdict
from dataclasses import dataclass, field
from pathlib import Path

from aodv.statsfile import DaemonStats, StatsError, run_stats_files
from common import boundedfile

log = logging.getLogger(__name__)

MAX_ROBOTS = 1000  # topology.names.MAX_ROBOTS (the analysis reads results without topology)
MAX_CAPTURE_BYTES = 512 << 20  # a 10-robot run of 5000 steps captures about 20 MB a robot
# Frames of one capture: ten times what a robot of such a run captures (some 150,000), and
# what tshark reads in about 15 s. A sparse 300 MiB file holds 19.6 million empty records,
# which kept tshark busy past two minutes.
MAX_CAPTURE_FRAMES = 2_000_000
MAX_RECORD_BYTES = 262_144  # libpcap's largest snap length: no record of a capture is longer
MAX_BLOCK_BYTES = 1 << 20  # a pcapng block: a record and its options, or a header
_CHUNK = 1 << 20
MAX_LOG_BYTES = 1 << 20
PCAP_MAGICS = (b"\xd4\xc3\xb2\xa1", b"\xa1\xb2\xc3\xd4", b"\x4d\x3c\xb2\xa1", b"\xa1\xb2\x3c\x4d")
PCAPNG_MAGIC = b"\x0a\x0d\x0d\x0a"
_NAME = re.compile(r"r([1-9][0-9]{0,3})\.pcap(ng)?")


@dataclass
class Captures:
    """A run's readable captures by robot number, and those left out with why."""

    paths: dict[int, Path] = field(default_factory=dict)
    left_out: dict[str, str] = field(default_factory=dict)  # file name: why


def _inside(path: Path, root: Path) -> bool:
    real, top = os.path.realpath(path), os.path.realpath(root)
    return real == top or real.startswith(top.rstrip("/") + "/")


def _why_not(p: Path, run_dir: Path) -> str | None:
    """Why capture `p` cannot be read, or None."""
    if not _inside(p, run_dir / "pcaps"):
        return "a link out of the captures' directory"
    try:
        head = boundedfile.read(p, MAX_CAPTURE_BYTES, _header_only)
    except boundedfile.Refused as r:
        return boundedfile.describe(r)
    except _Header as h:
        head = h.head
    if len(head) < 24:
        return "empty or cut short (no capture header)"
    if head[:4] not in PCAP_MAGICS + (PCAPNG_MAGIC,):
        return "not a pcap or pcapng capture"
    return None


class _Header(Exception):
    def __init__(self, head: bytes):
        self.head = head


def _header_only(fd: int, st) -> None:
    """boundedfile.read's check: read the first bytes and stop (the file may be large)."""
    raise _Header(os.pread(fd, 24, 0))


def find(run_dir: Path) -> Captures:
    """The captures of `run_dir` that may be read, and the rest named (see the docstring)."""
    out = Captures()
    d = Path(run_dir) / "pcaps"
    try:
        entries = sorted(d.iterdir())
    except OSError:
        return out
    for p in entries:
        if not p.name.startswith("r") or ".pcap" not in p.name:
            continue
        m = _NAME.fullmatch(p.name)
        if m is None or int(m[1]) > MAX_ROBOTS:
            out.left_out[p.name[:80]] = f"not a robot's capture name (r1 to r{MAX_ROBOTS})"
            continue
        why = _why_not(p, Path(run_dir))
        if why is not None:
            out.left_out[p.name] = why
        else:
            out.paths[int(m[1])] = p
    if out.paths:  # a robot between 1 and the last with no capture at all
        for k in range(1, max(out.paths)):
            if k not in out.paths and not any(n.startswith(f"r{k}.") for n in out.left_out):
                out.left_out[f"r{k}.pcap"] = "missing"
    for name, why in out.left_out.items():
        log.warning("%s: capture %s left out: %s", run_dir, name, why)
    return out


class _Bad(Exception):
    """A capture whose records are not a capture's (str(): why, one line)."""


def _pcap_frames(f, size: int, head: bytes) -> int:
    """The frames of a pcap capture (f after its 24-byte header); _Bad when a record claims
    more than MAX_RECORD_BYTES or the capture holds more than MAX_CAPTURE_FRAMES. A last
    record cut short (a run killed mid-write) ends the count: tshark reads up to it."""
    rec = struct.Struct("<I" if head[:4] in (PCAP_MAGICS[0], PCAP_MAGICS[2]) else ">I")
    data, base, off, frames = b"", 24, 24, 0
    while off + 16 <= size:
        at = off - base
        if at + 16 > len(data):
            f.seek(off)
            data, base, at = f.read(_CHUNK), off, 0
            if len(data) < 16:
                break
        length = rec.unpack_from(data, at + 8)[0]
        if length > MAX_RECORD_BYTES:
            left = size - off - 16
            raise _Bad(f"record {frames + 1} claims {length} bytes, more than any capture's "
                       f"record ({MAX_RECORD_BYTES}); the file has {left} left")  # fmt: skip
        frames += 1
        if frames > MAX_CAPTURE_FRAMES:
            raise _Bad(f"more than {MAX_CAPTURE_FRAMES:,} frames (docs/security.md)")
        off += 16 + length
    return frames


_PCAPNG_FRAMES = (2, 3, 6)  # packet, simple packet and enhanced packet blocks


def _pcapng_frames(f, size: int) -> int:
    """The frames of a pcapng capture, as _pcap_frames: each block at most MAX_BLOCK_BYTES,
    a whole number of 32-bit words of at least 12 bytes."""
    off, frames, order = 0, 0, "<"
    while off + 12 <= size:
        f.seek(off)
        block = f.read(12)
        if len(block) < 12:
            break
        if block[:4] == PCAPNG_MAGIC:  # a section header: its byte order from here on
            order = {b"\x4d\x3c\x2b\x1a": "<", b"\x1a\x2b\x3c\x4d": ">"}.get(block[8:12], "")
            if not order:
                raise _Bad(f"a section header at byte {off} of no known byte order")
        kind, length = struct.unpack(order + "II", block[:8])
        if length < 12 or length % 4 or length > MAX_BLOCK_BYTES:
            raise _Bad(f"a block of {length} bytes at byte {off} (12..{MAX_BLOCK_BYTES}, in "
                       f"words); the file has {size - off} left")  # fmt: skip
        if kind in _PCAPNG_FRAMES:
            frames += 1
            if frames > MAX_CAPTURE_FRAMES:
                raise _Bad(f"more than {MAX_CAPTURE_FRAMES:,} frames (docs/security.md)")
        off += length
    return frames


def count_frames(p: Path) -> int:
    """The frames capture `p` holds (find() took it: a regular file with a capture's
    header); _Bad when its records are not a capture's (see _pcap_frames)."""
    fd = os.open(p, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    with os.fdopen(fd, "rb") as f:
        size = os.fstat(fd).st_size
        head = f.read(24)
        if head[:4] == PCAPNG_MAGIC:
            return _pcapng_frames(f, size)
        return _pcap_frames(f, size, head)


def _digest(p: Path) -> str:
    return content_stamp([p])[p.name]


def _alike(out: Captures, groups, what: str) -> None:
    """Leave out every capture of each group of more than one, naming the others."""
    for ks in groups:
        for k in ks if len(ks) > 1 else ():
            others = ", ".join(f"r{j}.pcap" for j in ks if j != k)
            out.left_out[out.paths[k].name] = f"the same {what} as {others}: whose is unknown"


def checked(found: Captures) -> Captures:
    """The captures of `found` that may be given to tshark, the rest left out and named
    too: a capture whose records are not a capture's (a record longer than any, more than
    MAX_CAPTURE_FRAMES frames), and captures that are one file (the same device and inode:
    a hard link) or hold the same frames byte for byte: every one of them, since whose it is
    cannot be told, and read as several robots' it makes a delivery above 1 and delays of 0.
    Captures with no frame may be alike (robots that sent and heard nothing)."""
    out = Captures(dict(found.paths), dict(found.left_out))
    frames: dict[int, int] = {}
    for k, p in sorted(found.paths.items()):
        try:
            frames[k] = count_frames(p)
        except (_Bad, OSError) as e:
            out.left_out[p.name] = str(e)[:200]
            del out.paths[k]
    inodes: defaultdict[tuple[int, int], list[int]] = defaultdict(list)
    for k, p in out.paths.items():
        st = os.stat(p)
        inodes[st.st_dev, st.st_ino].append(k)
    _alike(out, inodes.values(), "file")
    sizes: defaultdict[int, list[int]] = defaultdict(list)
    for k, p in out.paths.items():
        if frames[k] and p.name not in out.left_out:
            sizes[p.stat().st_size].append(k)
    digests: defaultdict[str, list[int]] = defaultdict(list)
    for ks in sizes.values():
        for k in ks if len(ks) > 1 else ():
            digests[_digest(out.paths[k])].append(k)
    _alike(out, digests.values(), "bytes")
    for name in set(out.left_out) - set(found.left_out):
        log.warning("capture %s left out: %s", name, out.left_out[name])
    out.paths = {k: p for k, p in out.paths.items() if p.name not in out.left_out}
    return out


def content_stamp(paths: list[Path]) -> dict[str, str]:
    """{file name: SHA-256 of its content}: what routing.json's cache is keyed on."""
    out = {}
    for p in paths:
        h = hashlib.sha256()
        with open(p, "rb") as f:  # find() checked it is a regular file
            while chunk := f.read(1 << 20):
                h.update(chunk)
        out[p.name] = h.hexdigest()
    return out


_SHARES = ("pdf", "segment_delivery", "overhead_packets", "overhead_bytes")
_AMOUNTS = ("duration_s", "throughput_bps", "tx_packets", "control_tx_packets")
_DELAYS = ("delay_ms_mean", "delay_ms_median", "delay_ms_p95")


def cache_refusal(doc) -> str | None:
    """Why a cached routing.json is not taken (then its metrics are computed again from
    the captures), or None: shares outside 0..1, amounts below 0, delays beyond a day, or
    anything not a finite number. A cache is keyed on its captures' content, but a
    directory from elsewhere may ship captures and a cache written to go with them."""
    if not isinstance(doc, dict):
        return "not an object"
    for keys, low, high in ((_SHARES, 0, 1), (_AMOUNTS, 0, 1e18), (_DELAYS, -86.4e6, 86.4e6)):
        for k in keys:
            v = doc.get(k)
            if v is None:
                continue
            if isinstance(v, bool) or not isinstance(v, int | float) or not low <= v <= high:
                return f"{k} {str(v)[:40]} is not in {low:g}..{high:g}"
    return None


def daemon_counts(run_dir: Path) -> dict[str, dict] | None:
    """Per robot, what its AODV daemon says it transmitted (aodv/rK.json, read through its
    type, aodv.statsfile): {"packets": n, "bytes": UDP payload bytes, "by_type": {...}}.
    None if the run has no such files; a file that is not one is left out, said so."""
    files = run_stats_files(run_dir)
    if files is None:
        return None
    out = {}
    for p in files:
        try:
            stats = DaemonStats.read(p)
        except StatsError as e:
            log.warning("unreadable AODV counters: %s", e)
            continue
        by_type = Counter(stats.messages_sent)
        # What the kernel took but reported back untransmitted (a unicast whose next hop's
        # ARP failed) never reaches wlan0, so no capture can hold it.
        unsent = Counter(stats.messages_not_transmitted)
        by_type.subtract(unsent)
        out[p.stem[:40]] = {
            "packets": sum(by_type.values()),
            "bytes": stats.bytes_sent - stats.bytes_not_transmitted,
            "by_type": {k[:40]: n for k, n in by_type.items() if n},
            "not_transmitted": sum(unsent.values()),
        }
    return out or None


def capture_drops(run_dir: Path) -> dict[str, int]:
    """Per robot, the packets its capture lost in the kernel (tcpdump's last words, "N packets
    dropped by kernel", in pcaps/daemons/rK.tcpdump.log): what no count from the pcaps can
    include. Robots whose log has no such line (or is not a regular file) are left out."""
    out = {}
    for p in sorted((Path(run_dir) / "pcaps" / "daemons").glob("r*.tcpdump.log")):
        try:
            text = boundedfile.read(p, MAX_LOG_BYTES).decode(errors="replace")
        except boundedfile.Refused as r:
            log.warning("%s: not read: %s", p, boundedfile.describe(r))
            continue
        m = re.search(r"(?<![0-9])([0-9]{1,15}) packets? dropped by kernel", text)
        if m:
            out[p.name.split(".")[0][:40]] = int(m[1])
    return out
