"""What the AODV parameter sets change, in memory (aodv/sim.py: the real cores, encoded
messages, a fake clock): ten nodes walking to random waypoints at 1 m/s on 40 x 40 m, linked
within 12 m, six flows of two packets a second, 120 s, SEEDS seeds. Per parameter set: the
share of data packets delivered and the control messages sent, by kind.

Sets: `legacy` (what the daemon ran until 2026-11-24: the section 10 table's
MY_ROUTE_TIMEOUT 6 s and BLACKLIST_TIMEOUT 5.6 s, TTL_START 1, no local repair), `rfc`, `ns3`,
and `rfc` without local repair, to show what local repair alone does.
"""

import math
import random
from dataclasses import replace

from aodv.params import Params, profile
from aodv.sim import Medium
from testbed.bench.common import write

SEEDS = 8
NODES, SIZE_M, RANGE_M, SPEED, DURATION_S, DT = 10, 40.0, 12.0, 1.0, 120.0, 0.1
LEGACY = replace(
    Params(), my_route_timeout_ms=6000, blacklist_timeout_ms=5600, ttl_start=1,
    local_repair=False,
)  # fmt: skip


def scenario(params: Params, seed: int) -> tuple[int, int, dict[str, int]]:
    rnd = random.Random(seed)
    m = Medium(params)
    addrs = [f"10.0.0.{i}" for i in range(1, NODES + 1)]
    for a in addrs:
        m.add_node(a)
    pos = {a: [rnd.uniform(0, SIZE_M), rnd.uniform(0, SIZE_M)] for a in addrs}
    goal = {a: [rnd.uniform(0, SIZE_M), rnd.uniform(0, SIZE_M)] for a in addrs}
    flows = [pair for pair in ((rnd.choice(addrs), rnd.choice(addrs)) for _ in range(6))
             if pair[0] != pair[1]]  # fmt: skip
    sent, step = 0, 0
    while step * DT < DURATION_S:
        for a in addrs:
            dx, dy = goal[a][0] - pos[a][0], goal[a][1] - pos[a][1]
            d = math.hypot(dx, dy)
            if d < 0.2:
                goal[a] = [rnd.uniform(0, SIZE_M), rnd.uniform(0, SIZE_M)]
            else:
                pos[a][0] += SPEED * DT * dx / d
                pos[a][1] += SPEED * DT * dy / d
        m.links = {(a, b) for a in addrs for b in addrs
                   if a != b and math.dist(pos[a], pos[b]) <= RANGE_M}  # fmt: skip
        if step % 5 == 0:
            for src, dst in flows:
                m.send_data(src, dst)
                sent += 1
        step += 1
        m.run_until(step * DT)
    m.run_until(DURATION_S + 5)
    delivered = sum(len(m.nodes[a].delivered) for a in addrs)
    kinds: dict[str, int] = {}
    for msg in m.log:
        kinds[msg.kind] = kinds.get(msg.kind, 0) + 1
    return sent, delivered, kinds


def run() -> None:
    sets = {
        "legacy": LEGACY,
        "rfc": profile("rfc"),
        "ns3": profile("ns3"),
        "rfc_without_local_repair": replace(profile("rfc"), local_repair=False),
    }
    result = {"seeds": SEEDS, "scenario": __doc__.split("\n\n")[0]}
    for name, params in sets.items():
        sent = delivered = 0
        kinds: dict[str, int] = {}
        for seed in range(1, SEEDS + 1):
            s, d, k = scenario(params, seed)
            sent, delivered = sent + s, delivered + d
            for kind, n in k.items():
                kinds[kind] = kinds.get(kind, 0) + n
        result[name] = {"delivered": delivered / sent, "control_messages": sum(kinds.values()),
                        "by_kind": kinds}  # fmt: skip
        print(f"aodv_profiles: {name}: delivered {delivered / sent:.3f}, "
              f"{sum(kinds.values())} control messages")  # fmt: skip
    write("aodv_profiles", result)
