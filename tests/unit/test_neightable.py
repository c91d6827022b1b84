"""The host's ARP table, read (topology.kernel.neightable), and the fidelity verdict's use
of its overflows during a run's steps (testbed.run.fidelity.with_neighbour_table)."""

from testbed.run import fidelity
from topology.kernel import neightable

STATS = (
    "entries  allocs   destroys hash_grows lookups  hits     res_failed rcv_probes_mcast "
    "rcv_probes_ucast periodic_gc_runs forced_gc_runs unresolved_discards table_fulls\n"
    "00000001 00031ae5 0003f5c4 00000001   0086c078 001ec00b 000006c6   00000000         "
    "00000000         00000b4d         0015483a       00000000            0000000a\n"
    "00000001 00034784 00026ca4 0000000a   0085df5e 001dcbe3 000006cd   00000000         "
    "00000000         00000000         00146f8b       00000000            00000105\n"
)


def test_table_fulls_sums_every_cpu_in_hex(tmp_path):
    p = tmp_path / "arp_cache"
    p.write_text(STATS)
    assert neightable.table_fulls(str(p)) == 0x0A + 0x105


def test_an_unreadable_or_strange_file_is_none(tmp_path):
    assert neightable.table_fulls(str(tmp_path / "missing")) is None
    (tmp_path / "odd").write_text("entries allocs\n1 2\n")
    assert neightable.table_fulls(str(tmp_path / "odd")) is None
    (tmp_path / "bad").write_text(STATS.replace("00000105", "zz"))
    assert neightable.table_fulls(str(tmp_path / "bad")) is None
    assert neightable.limit(str(tmp_path / "missing")) is None
    (tmp_path / "thresh").write_text("1024\n")
    assert neightable.limit(str(tmp_path / "thresh")) == 1024


def test_this_hosts_table_is_read():
    assert isinstance(neightable.table_fulls(), int)
    assert (neightable.limit() or 0) > 0


def test_a_full_table_during_the_steps_makes_the_run_not_faithful():
    ok = {"ok": True, "measures": {}, "thresholds": {}}
    late = {"ok": False, "reason": "3.1% of step deadlines missed", "measures": {}}
    for fulls in (None, 0):
        kept = fidelity.with_neighbour_table(ok, fulls, 1024)
        assert kept["ok"] is True and "reason" not in kept
        assert kept["neighbour_table"] == {"fulls": fulls, "limit": 1024}
    full = fidelity.with_neighbour_table(ok, 7, 1024)
    assert full["ok"] is False
    assert "table was full 7 times" in full["reason"] and "limit 1024" in full["reason"]
    both = fidelity.with_neighbour_table(late, 2, None)
    assert both["ok"] is False
    assert both["reason"].startswith("3.1% of step deadlines missed; the host's neighbour")
