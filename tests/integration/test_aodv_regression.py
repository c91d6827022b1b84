"""ns-3's aodv-regression scenario in real namespaces, checked from the pcaps.

A chain of 5 robots (8 m apart, range 10 m); robot 1 pings robot 5; at one third of the
run the middle robot moves out of range, at two thirds it comes back. Time scale 5, so the
6 s run is 30 s of protocol time. Expected on robot 1's radio: RREQ/RREP, echo traffic, a
RERR for robot 5, RREQs while the chain is cut, and echo replies again at the end. The
ping runs 4.5 s past the return: a rediscovery begun while the chain was cut may have to
fail first (21 s of protocol time, 4.2 s here) before the next one succeeds.
"""

import re
import subprocess
import tempfile
import time

from tests.integration.test_aodv_daemon import CHAIN5, aodv_net, stats

T = 6.0


def tshark(path, *fields, filt="aodv"):
    out = subprocess.run(
        ["tshark", "-r", path, "-Y", filt, "-T", "fields",
         *sum((["-e", f] for f in fields), [])],
        capture_output=True, text=True, check=True,
    ).stdout  # fmt: skip
    return [line.split("\t") for line in out.splitlines()]


def test_aodv_regression_middle_robot_leaves_and_returns():
    with tempfile.TemporaryDirectory(prefix="ta-reg-") as cap:
        with aodv_net(CHAIN5, time_scale=5.0, capture_dir=cap) as net:
            pinger = net.spawn(
                1, ["ping", "-n", "-D", "-i", "0.1", "-c", str(int(10 * (T + 4.5))), "10.0.0.5"],
                role="test", stdout=subprocess.PIPE, text=True,
            )  # fmt: skip
            t0 = time.time()
            time.sleep(T / 3)
            net.move(3, (16.0, 50.0))
            t_leave = time.time()
            time.sleep(T / 3)
            net.move(3, (16.0, 0.0))
            t_back = time.time()
            text, _ = pinger.communicate(timeout=30)
            s1 = stats(net, 1)
            time.sleep(0.3)
        replies = [float(t) for t in re.findall(r"^\[(\d+\.\d+)\] 64 bytes", text, re.M)]
        assert [t for t in replies if t < t_leave], text
        assert not [t for t in replies if t_leave + 0.5 < t < t_back], text
        assert [t for t in replies if t > t_back], text
        assert s1["messages_received"].get("RERR", 0) >= 1

        rows = tshark(f"{cap}/r1.pcap", "frame.time_epoch", "ip.src", "ip.dst", "aodv.type",
                      "aodv.unreach_dest_ip", "aodv.orig_ip")  # fmt: skip
        kinds = [(float(r[0]), r[1], r[2], r[3], r[4], r[5]) for r in rows]
        first_rreq = min(k[0] for k in kinds if k[3] == "1" and k[1] == "10.0.0.1")
        first_rrep = min(k[0] for k in kinds if k[3] == "2" and k[2] == "10.0.0.1")
        assert t0 - 1 < first_rreq < first_rrep < t_leave
        rerrs = [k for k in kinds if k[3] == "3" and k[2] in ("10.0.0.1", "255.255.255.255")]
        assert rerrs and all(t_leave < k[0] < t_back for k in rerrs)
        assert any("10.0.0.5" in k[4].split(",") for k in rerrs)
        rediscovery = [k for k in kinds if k[3] == "1" and k[1] == "10.0.0.1" and k[0] > t_leave]
        assert rediscovery
        assert [k for k in kinds if k[3] == "2" and k[2] == "10.0.0.1" and k[0] > t_back]
