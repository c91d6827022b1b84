"""The ns3-wifi channel's relay-lag records: the file, following a packet's hops, and the
delays pcapmetrics corrects with them (synthetic captures and records)."""

import json

import pytest

from testbed.analysis import pcapmetrics as pm
from testbed.analysis import relaylag as rl
from testbed.analysis import routingnotes, runs
from testbed.analysis.pcapmetrics import Frame
from topology import names

M1, M2, M3 = "02:00:0a:00:00:01", "02:00:0a:00:00:02", "02:00:0a:00:00:03"
A1, A2, A3 = "10.0.0.1", "10.0.0.2", "10.0.0.3"
ADDRS = {1: A1, 2: A2, 3: A3}
T0 = 1_700_000_000.0  # CLOCK_REALTIME seconds, like the captures'


def approx(x):
    """Equal to within a microsecond in ms (times near T0 carry about 0.2 us)."""
    return pytest.approx(x, abs=1e-3)


def record(written, receiver, sender, in_us, out_us, src=A1, dst=A3, ip_id=7, proto=6, seq=1000):
    return rl.LagRecord(
        written=written, in_ns=int(in_us * 1000), out_ns=int(out_us * 1000), receiver=receiver,
        sender=sender, ethertype=rl.ETH_IPV4, ip_id=ip_id, ip_src=src, ip_dst=dst,
        tcp_seq=seq if proto == 6 else 0, ip_proto=proto,
    )  # fmt: skip


def packed(r: rl.LagRecord) -> bytes:
    def ip(a):
        return bytes(int(x) for x in a.split(".")) if a else b"\0" * 4

    return rl.RECORD.pack(
        round(r.written * 1e9), r.in_ns, r.out_ns, r.receiver, r.sender, r.ethertype, r.ip_id,
        ip(r.ip_src), ip(r.ip_dst), r.tcp_seq, r.ip_proto, r.tcp_flags, 0,
    )  # fmt: skip


def test_the_file_is_read_back_as_written_and_a_cut_record_is_left_out():
    recs = [record(T0 + 0.001, 2, 1, 40, 150), record(T0 + 0.002, 3, 2, 60, 90.5)]
    data = rl.MAGIC + b"".join(packed(r) for r in recs)
    assert rl.parse_records(data) == (recs, 0)
    assert rl.parse_records(data + packed(recs[0])[:17]) == (recs, 17)
    arp = rl.LagRecord(T0, 1, 2, 1, 2, 0x0806)
    (back,), _ = rl.parse_records(rl.MAGIC + packed(arp))
    assert back.ip_src == "" and back.ethertype == 0x0806  # not IPv4: no identity
    with pytest.raises(rl.LagFileError):
        rl.parse_records(b"TBRLAG02" + packed(recs[0]))


KEY = rl.packet_key(A1, A3, 7, 6, 1000)


def test_a_two_hop_packet_collects_both_hops_and_nothing_else():
    hop1, hop2 = record(T0 + 0.003, 2, 1, 50, 200), record(T0 + 0.009, 3, 2, 70, 180)
    others = [
        record(T0 + 0.004, 3, 1, 10, 10, ip_id=8),  # another packet
        record(T0 + 0.5, 3, 2, 10, 10),  # the same packet id much later (wraparound)
        record(T0 - 0.5, 2, 1, 10, 10),  # ... and much earlier
    ]
    index = rl.LagIndex([hop2, *others, hop1])
    assert index.path_lag(KEY, 1, 3, T0, T0 + 0.010) == [hop1, hop2]


def test_a_broadcast_counts_only_the_hop_to_each_receiver():
    # r1 broadcasts one UDP packet; r2 and r3 both hear it, each after its own lag.
    key = rl.packet_key(A1, "255.255.255.255", 9, 17, None)
    to2 = record(T0 + 0.001, 2, 1, 50, 100, dst="255.255.255.255", ip_id=9, proto=17)
    to3 = record(T0 + 0.0012, 3, 1, 50, 300, dst="255.255.255.255", ip_id=9, proto=17)
    index = rl.LagIndex([to2, to3])
    assert index.path_lag(key, 1, 2, T0, T0 + 0.0011) == [to2]
    assert index.path_lag(key, 1, 3, T0, T0 + 0.0013) == [to3]


def test_a_broken_chain_or_a_loop_matches_nothing():
    hop2 = record(T0 + 0.009, 3, 2, 70, 180)
    assert rl.LagIndex([hop2]).path_lag(KEY, 1, 3, T0, T0 + 0.010) is None  # hop 1 missing
    unknown = record(T0 + 0.009, 3, 0, 70, 180)  # a frame that lost its tag
    assert rl.LagIndex([unknown]).path_lag(KEY, 1, 3, T0, T0 + 0.010) is None
    loop = [record(T0 + 0.004, 2, 3, 1, 1), record(T0 + 0.006, 3, 2, 1, 1)]
    assert rl.LagIndex(loop).path_lag(KEY, 1, 3, T0, T0 + 0.010) is None
    late = record(T0 + 0.02, 3, 1, 70, 180)  # written after the receipt: not this packet's
    assert rl.LagIndex([late]).path_lag(KEY, 1, 3, T0, T0 + 0.010) is None


def tcp(t, src_mac, dst_mac, seq, ip_id, length=100):
    return Frame(T0 + t, 66 + length, src_mac, dst_mac, A1, A3, 6, 64, tcp_sport=40000,
                 tcp_dport=5555, tcp_seq=seq, tcp_len=length, ip_id=ip_id)  # fmt: skip


def chain():
    """r1 -> r2 -> r3: three segments, 10 ms each end to end (wall)."""
    c1, c2, c3 = [], [], []
    for i, seq in enumerate((1000, 1100, 1200)):
        t, ip_id = i * 0.1, 7 + i
        c1.append(tcp(t, M1, M2, seq, ip_id))
        c2.append(tcp(t + 0.004, M1, M2, seq, ip_id))
        c2.append(tcp(t + 0.005, M2, M3, seq, ip_id))
        c3.append(tcp(t + 0.010, M2, M3, seq, ip_id))
    return {1: c1, 2: c2, 3: c3}


def chain_lags():
    """Both hops of the first two segments, none of the third."""
    out = []
    for i, seq in enumerate((1000, 1100)):
        t, ip_id = i * 0.1, 7 + i
        out.append(record(T0 + t + 0.0039, 2, 1, 500, 1500, ip_id=ip_id, seq=seq))
        out.append(record(T0 + t + 0.0099, 3, 2, 1000, 1000, ip_id=ip_id, seq=seq))
    return out


def test_delays_have_their_hops_lag_taken_out_and_unmatched_ones_are_counted():
    m = pm.compute(chain(), ADDRS, lags=chain_lags())
    assert m["delay_raw_ms_median"] == approx(10.0)
    # 4 ms of lag out of the first two segments; the third stays at 10 ms.
    assert sorted([m["delay_ms_median"], m["delay_ms_p95"]]) == approx([6.0, 10.0])
    assert m["delay_ms_mean"] == approx((6 + 6 + 10) / 3)
    assert m["relay_lag"] == {
        "records": 4, "segments_corrected": 2, "segments_uncorrected": 1,
        "subtracted_ms_mean": approx(4.0), "subtracted_ms_median": approx(4.0),
    }  # fmt: skip


def test_without_lag_records_the_delays_and_keys_are_as_before():
    plain = pm.compute(chain(), ADDRS)
    assert plain["delay_ms_median"] == approx(10.0)
    assert not any(k.startswith("delay_raw") or k == "relay_lag" for k in plain)
    corrected = pm.compute(chain(), ADDRS, lags=chain_lags())
    assert set(corrected) - set(plain) == {
        "delay_raw_ms_mean", "delay_raw_ms_median", "delay_raw_ms_p95", "relay_lag",
    }  # fmt: skip
    assert routingnotes.about(False) == routingnotes.ABOUT
    assert "relay_lag" in routingnotes.about(True)


def test_emulated_time_carries_the_raw_delays_too():
    m = pm.compute(chain(), ADDRS, lags=chain_lags())
    e = routingnotes.emulated(m, 2.0)
    assert e["delay_raw_ms_median"] == approx(20.0)
    assert e["delay_ms_mean"] == approx(2 * (6 + 6 + 10) / 3)
    assert "delay_raw_ms_median" not in routingnotes.emulated(pm.compute(chain(), ADDRS), 2.0)


def test_ip_id_is_read_from_tsharks_hex():
    line = "\t".join(["1.5", "120", M1, M2, A1, A3, "6", "64", "", "", "", "40000", "5555",
                      "1000", "54", "", "", "0", "0x1a2b"])  # fmt: skip
    (f,) = pm.parse_fields(line)
    assert f.ip_id == 0x1A2B


def test_a_run_with_a_lag_file_that_is_not_one_is_one_line(tmp_path):
    (tmp_path / "result.json").write_text(json.dumps({"status": "complete"}))
    (tmp_path / names.LAG_FILE).write_bytes(b"garbage!")
    with pytest.raises(runs.ResultError) as e:
        runs.load_run(tmp_path)
    assert names.LAG_FILE in str(e.value) and "\n" not in str(e.value)
