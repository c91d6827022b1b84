"""Routing metrics on hand-made frames (the real-capture test is in tests/integration)."""

import json
import shutil
import socket
import struct
import subprocess

import pytest

from testbed.analysis import pcapmetrics as pm
from testbed.analysis.pcapmetrics import Frame

M1, M2, M3 = "02:00:00:00:00:01", "02:00:00:00:00:02", "02:00:00:00:00:03"
A1, A2, A3 = "10.0.0.1", "10.0.0.2", "10.0.0.3"
BCAST_MAC = "ff:ff:ff:ff:ff:ff"
ADDRS = {1: A1, 2: A2, 3: A3}


def udp(t, src_mac, dst_mac, src, dst, aodv_type, ttl=64, payload=24, port=654):
    return Frame(t, 42 + payload, src_mac, dst_mac, src, dst, 17, ttl, port, port, payload + 8,
                 aodv_type=aodv_type)  # fmt: skip


def tcp(t, src_mac, dst_mac, src, dst, seq, length, sport=40000, dport=5555):
    return Frame(t, 66 + length, src_mac, dst_mac, src, dst, 6, 64, tcp_sport=sport,
                 tcp_dport=dport, tcp_seq=seq, tcp_len=length)  # fmt: skip


def chain_captures():
    """1 - 3 - 2: robot 1 sends 3 segments to robot 2 through robot 3; the third is lost on
    the second hop; AODV control traffic on the way."""
    c1 = [
        udp(0.0, M1, BCAST_MAC, A1, "255.255.255.255", 1),  # RREQ
        udp(0.1, M3, M1, A2, A1, 2),  # RREP forwarded by 3
        tcp(1.0, M1, M3, A1, A2, 1000, 100),
        tcp(1.1, M1, M3, A1, A2, 1100, 100),
        tcp(1.2, M1, M3, A1, A2, 1200, 100),
        tcp(1.05, M3, M1, A2, A1, 5000, 0),  # an ACK: no payload, not a message
        udp(2.0, M1, BCAST_MAC, A1, "255.255.255.255", 2, ttl=1, payload=20),  # HELLO
    ]
    c3 = [
        udp(0.0, M1, BCAST_MAC, A1, "255.255.255.255", 1),
        udp(0.01, M3, BCAST_MAC, A1, "255.255.255.255", 1),  # rebroadcast RREQ
        udp(0.09, M2, M3, A2, A1, 2),
        udp(0.1, M3, M1, A2, A1, 2),  # forwarded RREP
        udp(0.5, M3, BCAST_MAC, A3, "255.255.255.255", 2, ttl=1, payload=20),  # own HELLO
        tcp(1.0, M1, M3, A1, A2, 1000, 100),
        tcp(1.001, M3, M2, A1, A2, 1000, 100),
        tcp(1.1, M1, M3, A1, A2, 1100, 100),
        tcp(1.101, M3, M2, A1, A2, 1100, 100),
        tcp(1.2, M1, M3, A1, A2, 1200, 100),
        tcp(1.201, M3, M2, A1, A2, 1200, 100),
    ]
    c2 = [
        udp(0.01, M3, BCAST_MAC, A1, "255.255.255.255", 1),
        udp(0.09, M2, M3, A2, A1, 2),  # RREP
        tcp(1.003, M3, M2, A1, A2, 1000, 100),
        tcp(1.104, M3, M2, A1, A2, 1100, 100),
        tcp(1.05, M2, M3, A2, A1, 5000, 0),
    ]
    return {1: c1, 2: c2, 3: c3}


def test_overhead_counts_each_transmission_at_its_transmitter():
    m = pm.compute(chain_captures(), ADDRS)
    r1, r2, r3 = (m["robots"][f"r{k}"] for k in (1, 2, 3))
    assert (r1["mac"], r2["mac"], r3["mac"]) == (M1, M2, M3)
    assert r1["control_tx_packets"] == 2  # RREQ, HELLO
    assert r3["control_tx_packets"] == 3  # rebroadcast RREQ, forwarded RREP, HELLO
    assert r2["control_tx_packets"] == 1
    assert m["aodv_tx_by_type"] == {"RREQ": 2, "RREP": 2, "HELLO": 2}
    assert r1["tx_packets"] == 5 and r3["tx_packets"] == 6 and r2["tx_packets"] == 2
    assert m["overhead_packets"] == pytest.approx(6 / 13)
    assert r1["control_tx_payload_bytes"] == 24 + 20
    assert r1["control_rx_packets"] == 1


def test_delivery_delay_and_throughput():
    m = pm.compute(chain_captures(), ADDRS)
    assert m["tcp_segments_sent"] == 3
    assert m["tcp_segments_delivered"] == 2
    assert m["segment_delivery"] == pytest.approx(2 / 3)
    assert m["pdf"] == pytest.approx(200 / 300)  # forwarding by robot 3 is not a source
    assert m["delay_ms_mean"] == pytest.approx((3 + 4) / 2)
    assert m["delay_ms_median"] == pytest.approx(3.5)
    assert m["delivered_payload_bytes"] == 200
    assert m["throughput_bps"] == pytest.approx(8 * 200 / 2.0)  # captures span 0.0 .. 2.0


def test_retransmissions_and_resegmentation():
    caps = {
        1: [
            udp(0.0, M1, BCAST_MAC, A1, "255.255.255.255", 1),
            tcp(1.0, M1, M2, A1, A2, 0, 100),  # lost
            tcp(1.5, M1, M2, A1, A2, 0, 100),  # retransmission, arrives
            tcp(1.6, M1, M2, A1, A2, 100, 100),
            tcp(1.7, M1, M2, A1, A2, 200, 100),
        ],
        2: [
            udp(0.0, M2, BCAST_MAC, A2, "255.255.255.255", 1),
            tcp(1.501, M1, M2, A1, A2, 0, 100),
            tcp(1.702, M1, M2, A1, A2, 100, 200),  # GRO merged the last two segments
        ],
    }
    m = pm.compute(caps, {1: A1, 2: A2})
    assert m["tcp_segments_sent"] == 3 and m["tcp_transmissions"] == 4
    assert m["tcp_flows"] == 1  # one direction of one connection sent data
    assert m["segment_delivery"] == 1.0
    assert m["pdf"] == pytest.approx(300 / 400)
    assert m["tcp_transmissions_delivered"] == 3
    # delays: 1.0 -> 1.501 (first transmission to first reception), 1.6 -> 1.702, 1.7 -> 1.702
    assert m["delay_ms_mean"] == pytest.approx((501 + 102 + 2) / 3)


def test_icmp_quoting_port_654_is_not_aodv():
    icmp = Frame(1.0, 90, M1, M2, A1, A2, 1, 64, 654, 654, 32)  # inner UDP header fields
    caps = {1: [udp(0.0, M1, BCAST_MAC, A1, "255.255.255.255", 1), icmp], 2: []}
    m = pm.compute(caps, {1: A1, 2: A2})
    assert m["control_tx_packets"] == 1 and m["tx_packets"] == 2


def test_a_segment_without_a_sequence_number_is_not_matched_with_one_that_has_one():
    sent = tcp(1.0, M1, M2, A1, A2, 1000, 100)
    unnumbered = Frame(1.1, 166, M1, M2, A1, A2, 6, 64, tcp_sport=40000, tcp_dport=5555,
                       tcp_len=100)  # fmt: skip
    m = pm.compute({1: [sent], 2: [unnumbered]}, {1: A1, 2: A2})
    assert (m["tcp_segments_sent"], m["tcp_segments_delivered"]) == (1, 0)


def test_babel_port():
    caps = {1: [udp(0.0, M1, BCAST_MAC, A1, "ff02::1:6", None, port=6696)]}
    caps[1].append(udp(0.1, M1, BCAST_MAC, A1, "255.255.255.255", 1))
    assert pm.compute(caps, {1: A1}, port=6696)["control_tx_packets"] == 1


def test_parse_fields():
    line = "\t".join(
        ["12.5", "62", M1, BCAST_MAC, A1, "255.255.255.255", "17", "1", "654", "654", "28",
         "", "", "", "", "2", ""]
    )  # fmt: skip
    (f,) = pm.parse_fields(line + "\n\nnot\ta\tframe\n")
    assert f == udp(12.5, M1, BCAST_MAC, A1, "255.255.255.255", 2, ttl=1, payload=20)
    short = "1.0\t60\t" + M1 + "\t" + M2  # an ARP frame: no IP fields at all
    (g,) = pm.parse_fields(short)
    assert g.ip_src == "" and g.udp_sport is None


def daemon_doc(sent: dict, bytes_sent: int) -> str:
    """What aodv/stats.py writes (the fields the comparison reads, plus some it ignores)."""
    return json.dumps(
        {"robot": "r1", "messages_sent": sent, "messages_received": {}, "bytes_sent": bytes_sent,
         "bytes_received": 0, "dropped": {}, "discoveries_ok": 1}
    )  # fmt: skip


def test_daemon_comparison(tmp_path):
    (tmp_path / "aodv").mkdir()
    (tmp_path / "aodv" / "r1.json").write_text(daemon_doc({"RREQ": 1, "HELLO": 1}, 44))
    (tmp_path / "aodv" / "r3.json").write_text(daemon_doc({"RREQ": 1, "RREP": 1, "HELLO": 1}, 68))
    (tmp_path / "aodv" / "r2.json").write_text("{broken")
    daemons = pm.daemon_counts(tmp_path)
    assert daemons["r1"] == {
        "packets": 2, "bytes": 44, "by_type": {"RREQ": 1, "HELLO": 1}, "not_transmitted": 0
    }  # fmt: skip
    assert set(daemons) == {"r1", "r3"}
    cmp = pm.compare_with_daemons(pm.compute(chain_captures(), ADDRS), daemons)
    assert cmp["robots"] == ["r1", "r3"]
    assert cmp["pcap_control_tx_packets"] == 5 and cmp["daemon_tx_packets"] == 5
    assert cmp["relative_difference"] == 0.0
    assert cmp["pcap_control_tx_payload_bytes"] == 24 + 20 + 24 + 24 + 20
    assert cmp["relative_difference_bytes"] == pytest.approx(abs(112 - 112) / 112)
    assert cmp["by_type"]["HELLO"] == {"pcap": 2, "daemon": 2}
    # one message the capture missed shows as a difference
    (tmp_path / "aodv" / "r1.json").write_text(daemon_doc({"RREQ": 2, "HELLO": 1}, 68))
    cmp = pm.compare_with_daemons(pm.compute(chain_captures(), ADDRS), pm.daemon_counts(tmp_path))
    assert cmp["relative_difference"] == pytest.approx(1 / 6)
    # ... unless the daemon heard back from the kernel that it never went out (IP_RECVERR)
    doc = json.loads(daemon_doc({"RREQ": 2, "HELLO": 1}, 68))
    doc.update(messages_not_transmitted={"RREQ": 1}, bytes_not_transmitted=24)
    (tmp_path / "aodv" / "r1.json").write_text(json.dumps(doc))
    cmp = pm.compare_with_daemons(pm.compute(chain_captures(), ADDRS), pm.daemon_counts(tmp_path))
    assert cmp["relative_difference"] == 0.0 and cmp["relative_difference_bytes"] == 0.0
    assert cmp["by_type"]["RREQ"] == {"pcap": 2, "daemon": 2}
    assert pm.daemon_counts(tmp_path / "nothing") is None
    assert pm.compare_with_daemons({}, None) is None


def test_run_without_captures(tmp_path):
    assert pm.run_metrics(tmp_path) is None


def test_ipv6_udp_is_recognised():
    """babel speaks UDP 6696 over IPv6 link-local: the protocol comes from ipv6.nxt."""
    fields = ["1.0", "100", M1, "33:33:00:01:00:06", "", "", "", "", "6696", "6696", "40"]
    fields += ["", "", "", "", "", "17"]
    (f,) = pm.parse_fields("\t".join(fields))
    assert f.ip_proto == 17
    caps = {1: [f, udp(0.0, M1, BCAST_MAC, A1, "255.255.255.255", None, port=5000)]}
    m = pm.compute(caps, {1: A1}, port=6696)
    assert m["control_tx_packets"] == 1 and m["tx_packets"] == 2


def test_capture_drops_are_read_from_tcpdumps_last_words(tmp_path):
    logs = tmp_path / "pcaps" / "daemons"
    logs.mkdir(parents=True)
    (logs / "r1.tcpdump.log").write_text(
        "tcpdump: listening on wlan0, link-type EN10MB (Ethernet), snapshot length 262144 bytes\n"
        "5137 packets captured\n5149 packets received by filter\n12 packets dropped by kernel\n"
    )
    (logs / "r2.tcpdump.log").write_text("0 packets dropped by kernel\n")
    (logs / "r3.tcpdump.log").write_text("tcpdump: listening on wlan0\n")  # killed: no summary
    (logs / "r1.aodv.log").write_text("99 packets dropped by kernel\n")  # not a capture's log
    assert pm.capture_drops(tmp_path) == {"r1": 12, "r2": 0}
    assert pm.capture_drops(tmp_path / "none") == {}


# ---------------------------------------------------------------- real files, real tshark


def _pcap_record(t: float, src_mac: str, src: str, payload: bytes) -> bytes:
    """One Ethernet/IPv4/UDP 654 broadcast frame as a pcap record (checksums left zero)."""
    udp_hdr = struct.pack("!HHHH", 654, 654, 8 + len(payload), 0)
    total = 20 + len(udp_hdr) + len(payload)
    ip_hdr = struct.pack("!BBHHHBBH4s4s", 0x45, 0, total, 0, 0, 1, 17, 0,
                         socket.inet_aton(src), socket.inet_aton("255.255.255.255"))  # fmt: skip
    eth = bytes.fromhex("ff" * 6) + bytes.fromhex(src_mac.replace(":", "")) + b"\x08\x00"
    frame = eth + ip_hdr + udp_hdr + payload
    sec, usec = int(t), round((t - int(t)) * 1e6)
    return struct.pack("<IIII", sec, usec, len(frame), len(frame)) + frame


def _write_pcap(path, records: list[bytes]) -> None:
    header = struct.pack("<IHHiIII", 0xA1B2C3D4, 2, 4, 0, 0, 262144, 1)  # Ethernet
    path.write_bytes(header + b"".join(records))


HELLO = bytes([2, 0, 0, 0]) + bytes(16)  # a RREP's 20 bytes: type 2


needs_tshark = pytest.mark.skipif(
    not all(shutil.which(t) for t in ("tshark", "mergecap")),
    reason="tshark and mergecap come with `make setup`",
)


@needs_tshark
def test_a_runs_captures_are_read_with_one_tshark_and_split_back(tmp_path, caplog):
    """Interleaved timestamps across files: each frame goes back to the capture it came from,
    and the merged read gives what reading each file alone gives."""
    robots = {1: (M1, A1), 2: (M2, A2), 10: (M3, A3)}
    paths = {}
    for k, (mac, addr) in robots.items():
        paths[k] = tmp_path / f"r{k}.pcap"
        times = [100.0 + k * 0.001 + i * 0.5 for i in range(k + 2)]
        _write_pcap(paths[k], [_pcap_record(t, mac, addr, HELLO) for t in times])
    merged = pm.read_pcaps(paths)
    assert "reading each" not in caplog.text  # the merged read itself succeeded
    assert {k: len(v) for k, v in merged.items()} == {1: 3, 2: 4, 10: 12}
    for k, frames in merged.items():
        assert {f.ip_src for f in frames} == {robots[k][1]}
        alone = pm.read_pcap(paths[k])
        assert [(f.time, f.eth_src, f.aodv_type) for f in frames] == [
            (f.time, f.eth_src, f.aodv_type) for f in alone
        ]
        assert all(f.aodv_type == 2 and f.udp_dport == 654 for f in frames)


@needs_tshark
def test_a_capture_cut_short_is_read_alone_and_nothing_else_is_lost(tmp_path, caplog):
    """Wireshark 3.x's mergecap stops at the first capture cut short (4.x reads up to the cut);
    where it stops, the reader falls back to one tshark per capture. Either way the whole of the
    intact one and what the cut one holds are both kept, and the fallback says so when taken."""
    paths = {1: tmp_path / "r1.pcap", 2: tmp_path / "r2.pcap"}
    _write_pcap(paths[1], [_pcap_record(1.0 + i, M1, A1, HELLO) for i in range(6)])
    _write_pcap(paths[2], [_pcap_record(1.5 + i, M2, A2, HELLO) for i in range(6)])
    data = paths[2].read_bytes()
    paths[2].write_bytes(data[: len(data) - 30])  # the last record cut in half
    frames = pm.read_pcaps(paths)
    assert len(frames[1]) == 6 and len(frames[2]) == 5
    merge = subprocess.run(
        ["mergecap", "-I", "none", "-F", "pcapng", "-w", str(tmp_path / "m.pcapng"),
         str(paths[1]), str(paths[2])],
        capture_output=True,
    )  # fmt: skip
    assert ("reading each" in caplog.text) == (merge.returncode != 0), caplog.text
