"""Packet capture: tcpdump on each robot's wlan0, inside its namespace, one pcap per robot.

Capturing on wlan0 records exactly what the robot's radio sent and received, which is what
the routing metrics are computed from. tcpdump is started before the routing daemons so the
first HELLO is in the file, and we wait for its "listening on" line so nothing is missed.
`--immediate-mode` hands each packet to tcpdump as it arrives (libpcap otherwise delivers
blocks on a 1 s timeout, and stopping tcpdump loses the block in progress: the last HELLOs
went missing), `-U` writes each packet as it comes, so a killed run still leaves readable
pcaps, and `-Z root` keeps Debian's tcpdump from dropping privileges and failing to write
into a root-owned directory. `-B` gives each capture a 16 MiB kernel buffer instead of
libpcap's 2 MiB: tcpdump runs at ordinary priority beside real-time robots, and with the
default a 10-robot run lost up to 273 packets in the kernel while tcpdump was not scheduled
(it says so on exit, "N packets dropped by kernel", in its log, kept next to the pcaps and
read by testbed.analysis.pcapmetrics). At teardown tcpdump is stopped after everything else, so the
routing daemons' last words are in the file.
"""

import os
import time

from topology import names

READY_TIMEOUT_S = 10.0
BUFFER_KIB = 16384


def pcap_path(capture_dir: str, k: int) -> str:
    return os.path.join(capture_dir, f"r{k}.pcap")


def tcpdump_argv(capture_dir: str, k: int) -> list[str]:
    return [
        "tcpdump", "-i", names.ROBOT_IFACE, "-n", "-s", "0", "-U", "--immediate-mode",
        "-B", str(BUFFER_KIB), "-Z", "root",
        "-w", pcap_path(capture_dir, k),
    ]  # fmt: skip


def wait_ready(log_path: str, proc, timeout: float = READY_TIMEOUT_S) -> None:
    """Block until tcpdump says it is listening; raise RuntimeError if it dies or stalls."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            with open(log_path) as f:
                text = f.read()
        except FileNotFoundError:
            text = ""
        if "listening on" in text:
            return
        if proc.poll() is not None:
            raise RuntimeError(f"tcpdump exited: {text.strip().splitlines()[-1:] or ['?']}")
        time.sleep(0.01)
    raise RuntimeError(f"tcpdump did not start listening within {timeout:.0f} s")
