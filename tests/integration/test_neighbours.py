"""A lone robot stays exact and faithful beside ordinary neighbours on the machine.

Each neighbour of testbed.bench.neighbours in turn (a disk writer syncing in a loop, another
testbed's ten-robot network brought up and torn down in a loop, two niced busy loops) runs
beside a lone robot of seed 2 at time scale 5: the run must be faithful and take exactly the
steps and the path of tests/data/lone-k5 (1989 steps). Before the AODV daemons' statistics
and logs left their loop, the disk writer made a HELLO timer seconds late in most such runs
(docs/measurements.md, "The AODV daemons' stalls"); with the compiled daemon, traced, what
is left of its timers' lateness is the machine's, under two fifths of the verdict's limit
("A lone robot beside neighbours, the compiled daemon traced").

One run each, no retry: a run the fidelity verdict cannot call exact is this test's failure.
The neighbour is stopped, and its network torn down, however the run ends."""

import pytest

from testbed.bench.neighbours import lone_run, neighbour

SEED = 2


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["disk", "churn", "busy"])
def test_a_lone_robot_is_exact_and_faithful_beside_a_neighbour(tmp_path, kind):
    with neighbour(kind, str(tmp_path)):
        r = lone_run(SEED, str(tmp_path / "run"))
    detail = {k: r[k] for k in ("steps", "reason", "world", "robot_process", "aodv", "display")}
    assert r["faithful"], f"not faithful beside {kind}: {detail}"
    assert r["exact"], f"not exact beside {kind}: {detail}"
