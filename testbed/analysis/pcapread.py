"""A run's packet captures read into frames, for the routing metrics
(testbed.analysis.pcapmetrics).

Theory of operation. tshark reads each capture (`-T fields`, the first occurrence of each of
`_FIELDS`, tab-separated) and `parse_fields` turns its lines into `Frame`s, checking every
number against its field's range so that nothing absurd reaches the metrics. A run's captures
are read with a single tshark process (`read_pcaps`): mergecap joins them as separate
interfaces and `frame.interface_id` says whose capture each frame came from; when mergecap
stops at a capture cut short, each is read on its own. UDP's payload is asked for only when
the middleware's framing is read from it (DDS's RTPS).
"""

from __future__ import annotations

import logging
import math
import os
import subprocess
import tempfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

log = logging.getLogger(__name__)

_FIELDS = (
    "frame.time_epoch",
    "frame.len",
    "eth.src",
    "eth.dst",
    "ip.src",
    "ip.dst",
    "ip.proto",
    "ip.ttl",
    "udp.srcport",
    "udp.dstport",
    "udp.length",
    "tcp.srcport",
    "tcp.dstport",
    "tcp.seq_raw",
    "tcp.len",
    "aodv.type",
    "ipv6.nxt",
    "frame.interface_id",  # in a merged capture, which input file the frame came from
    "ip.id",  # with the addresses, protocol and TCP sequence: a packet's identity across hops
    "tcp.payload",  # hex; the middleware's framing is read from it
)
# Asked for only when the middleware is DDS (its RTPS is read from it): written for every
# UDP frame, map floods included, it costs tshark a tenth more time on a large run.
_UDP_PAYLOAD = "udp.payload"


@dataclass(frozen=True)
class Frame:
    time: float
    length: int
    eth_src: str
    eth_dst: str
    ip_src: str = ""
    ip_dst: str = ""
    ip_proto: int | None = None
    ttl: int | None = None
    udp_sport: int | None = None
    udp_dport: int | None = None
    udp_len: int | None = None
    tcp_sport: int | None = None
    tcp_dport: int | None = None
    tcp_seq: int | None = None
    tcp_len: int | None = None
    aodv_type: int | None = None
    interface: int = 0
    ip_id: int | None = None
    tcp_payload: bytes = b""
    udp_payload: bytes = b""  # only when asked for (read_pcaps' udp_payload)


def _int(s: str, top: int = 0xFFFF) -> int | None:
    """A field tshark writes as a whole number 0..top (a port, a length: 0..65535 unless
    said), or None when empty; ValueError otherwise."""
    if not s:
        return None
    v = int(s) if len(s) <= 20 else -1  # (int() of 5000 digits is an error of its own)
    if not 0 <= v <= top:
        raise ValueError(f"{s[:20]!r} is not in 0..{top}")
    return v


_U32 = 0xFFFFFFFF


def _hex_int(s: str, top: int = 0xFFFF) -> int | None:
    """A field tshark writes in hex ("0x1a2b"; or in decimal), or None when empty;
    ValueError otherwise."""
    if not s:
        return None
    v = (int(s, 16) if s[:2].lower() == "0x" else int(s)) if len(s) <= 20 else -1
    if not 0 <= v <= top:
        raise ValueError(f"{s[:20]!r} is not in 0..{top}")
    return v


# A capture's clock: seconds since 1970. Up to the year 33658: far past any real capture, and
# small enough that no difference, sum or millisecond of two such times overflows a float.
MAX_TIME_S = 1e12


def _time(s: str) -> float:
    t = float(s)
    if not (math.isfinite(t) and 0 <= t <= MAX_TIME_S):
        raise ValueError(f"time {s[:20]!r}")
    return t


def parse_fields(text: str) -> list[Frame]:
    """Frames from tshark's tab-separated `-e` output in `_FIELDS` order. A line whose
    fields are not what tshark writes (a time that is not a number in 0..MAX_TIME_S, a number out
    of its field's range: lengths, ports and sequence numbers are unsigned of their size)
    is skipped with a warning, so that no NaN or absurd count reaches the metrics."""
    frames = []
    for line in text.splitlines():
        if not line:
            continue
        f = line.split("\t")
        f += [""] * (len(_FIELDS) + 1 - len(f))
        try:
            length = _int(f[1], _U32)
            if length is None:
                raise ValueError("no frame length")
            frames.append(
                Frame(
                    time=_time(f[0]),
                    length=length,
                    eth_src=f[2],
                    eth_dst=f[3],
                    ip_src=f[4],
                    ip_dst=f[5],
                    # IPv4 protocol or IPv6 next header
                    ip_proto=_int(f[6], 255) or _int(f[16], 255),
                    ttl=_int(f[7], 255),
                    udp_sport=_int(f[8]),
                    udp_dport=_int(f[9]),
                    udp_len=_int(f[10]),
                    tcp_sport=_int(f[11]),
                    tcp_dport=_int(f[12]),
                    tcp_seq=_int(f[13], _U32),
                    tcp_len=_int(f[14], _U32),
                    aodv_type=_int(f[15], 255),
                    interface=_int(f[17], _U32) or 0,
                    ip_id=_hex_int(f[18]),
                    tcp_payload=bytes.fromhex(f[19]),
                    udp_payload=bytes.fromhex(f[20]),
                )
            )
        except ValueError:
            log.warning("unparsable tshark line skipped: %r", line[:120])
    return frames


def _tshark_argv(path: str, udp_payload: bool = False) -> list[str]:
    argv = ["tshark", "-n", "-r", path, "-T", "fields", "-E", "separator=/t"]
    argv += ["-E", "occurrence=f"]
    for name in _FIELDS + ((_UDP_PAYLOAD,) if udp_payload else ()):
        argv += ["-e", name]
    return argv


def read_pcap(path: str | Path, udp_payload: bool = False) -> list[Frame]:
    """All frames of one capture (one tshark process); with `udp_payload`, UDP's payload
    too."""
    r = subprocess.run(_tshark_argv(str(path), udp_payload), capture_output=True, text=True)
    if r.returncode != 0:
        # tshark exits 2 on a capture cut short (a run killed mid-write); keep what it read.
        log.warning("tshark on %s: status %d: %s", path, r.returncode, r.stderr.strip()[-200:])
    return parse_fields(r.stdout)


def read_pcaps(paths: dict[int, Path], udp_payload: bool = False) -> dict[int, list[Frame]]:
    """All frames of several captures, by key, with one tshark process (`udp_payload` as
    for read_pcap).

    tshark spends 0.3-0.4 s starting up (its dissectors) and a robot's capture takes it a
    tenth of that to read, so a run's captures are read together: mergecap joins them into one
    pcapng stream with each file as its own interface (`-I none`, in the order given) and
    `frame.interface_id` maps each frame back to its file. mergecap stops at the first capture
    cut short (a run killed mid-write); then each capture is read on its own, which keeps
    everything every file holds."""
    keys = sorted(paths)
    if len(keys) < 2:
        return {k: read_pcap(paths[k], udp_payload) for k in keys}
    with tempfile.TemporaryFile() as merge_err:
        merge = subprocess.Popen(
            ["mergecap", "-I", "none", "-F", "pcapng", "-w", "-", *(str(paths[k]) for k in keys)],
            stdout=subprocess.PIPE,
            stderr=merge_err,
        )
        assert merge.stdout is not None  # stdout=PIPE
        try:
            r = subprocess.run(
                _tshark_argv("-", udp_payload),
                stdin=merge.stdout,
                capture_output=True,
                text=True,
            )
        finally:
            merge.stdout.close()
            merge.wait()
        merge_err.seek(0)
        why = merge_err.read().decode(errors="replace").strip()
    if merge.returncode != 0 or r.returncode != 0:
        why = why or r.stderr.strip()
        log.warning("merged read of %d captures failed (%s); reading each", len(keys), why[-200:])
        with ThreadPoolExecutor(max_workers=os.cpu_count() or 1) as pool:
            read = pool.map(lambda k: read_pcap(paths[k], udp_payload), keys)
            return dict(zip(keys, read, strict=True))
    out: dict[int, list[Frame]] = {k: [] for k in keys}
    for f in parse_fields(r.stdout):
        out[keys[f.interface]].append(f)
    return out
