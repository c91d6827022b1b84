"""The run check finds messages that arrived without a multi-hop path (it can fail)."""

import json

from testbed.analysis import runcheck


def write_run(d, links, recvs, robots=3, steps=20):
    (d / "robots").mkdir()
    config = {"robots": robots, "comm_range": 5.0, "laser_range": 2.0}
    doc = {"status": "complete", "config": config, "steps": steps}
    (d / "result.json").write_text(json.dumps(doc))
    rows = ["step,event,i,j"] + [f"{s},{e},{i},{j}" for s, e, i, j in links]
    (d / "links.csv").write_text("\n".join(rows) + "\n")
    for k in range(1, robots + 1):
        lines = [json.dumps({"e": "recv", **r}) for r in recvs if r["to"] == k]
        (d / "robots" / f"r{k}.events.jsonl").write_text("\n".join(lines) + "\n")


def test_multi_hop_and_store_free_paths(tmp_path):
    # 1-2 linked from step 0; 2-3 linked only from step 10 to 12.
    links = [(0, "add", 1, 2), (10, "add", 2, 3), (12, "remove", 2, 3)]
    ok = {"kind": "map", "frm": 1, "to": 3, "sent": 10, "step": 11}  # two hops at step 10
    late = {"kind": "goal", "frm": 3, "to": 1, "sent": 15, "step": 16}  # 3 isolated by then
    early = {"kind": "map", "frm": 1, "to": 3, "sent": 2, "step": 4}  # before 2-3 existed
    write_run(tmp_path, links, [ok, late, early])
    n, bad = runcheck.causality_violations(str(tmp_path), slack=1)
    assert n == 3
    assert sorted((b["frm"], b["to"], b["sent"]) for b in bad) == [(1, 3, 2), (3, 1, 15)]
    assert runcheck.heard_from(str(tmp_path), 3)[3] == {1}


def test_a_receipt_is_placed_at_the_worlds_step_when_the_robot_lags(tmp_path):
    # 1-3 linked only from step 10 to 12. Robot 1 sent at its step 7, robot 3 logged the
    # receipt at its step 4 (both were behind), when the world was at step 10: a path existed.
    links = [(10, "add", 1, 3), (12, "remove", 1, 3)]
    lagging = {"kind": "map", "frm": 1, "to": 3, "sent": 7, "step": 4, "t": 110.05}
    crossed = {"kind": "map", "frm": 1, "to": 3, "sent": 2, "step": 4, "t": 104.05}
    write_run(tmp_path, links, [lagging, crossed])
    n, bad = runcheck.causality_violations(str(tmp_path), slack=1)
    assert [b["t"] for b in bad] == [110.05, 104.05]  # without the clock, both look bad
    rows = ["step,t"] + [f"{s},{100 + s}" for s in range(21)]  # step s began at 100 + s
    (tmp_path / "clock.csv").write_text("\n".join(rows) + "\n")
    n, bad = runcheck.causality_violations(str(tmp_path), slack=1)
    assert n == 2 and [b["t"] for b in bad] == [104.05]  # sent at 2, received at 4: no path
