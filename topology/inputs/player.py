"""The trace player of `testbed net up --mobility FILE`: a process of its own that moves the
robots of a running testbed along a trace (topology.inputs.mobility) and writes the links it
applied.

Theory of operation. The player attaches to the testbed (topology.network.Network.attach) and
walks the ticks 0, T, 2T, ... of emulated time; tick t is due at wall time t / time_scale
after the start. At each tick it samples the trace, moves the robots whose position changed
(one batch, links follow before the call returns) and appends what changed to links.csv
(`time,event,i,j`, time in emulated seconds, time 0 the initial links), as a run's links.csv
does per step. A tick that comes late is still applied, in order: the timeline is exactly
the trace's, only its wall-clock times slip (the late ticks are counted in the log). After
the trace's end the final positions hold and the player exits; `net down` stops it earlier
by its recorded pid. Once tick 0 is applied it creates the `--ready` file: `net up` waits for
that, and reports the player's last log line if it exits first.
"""

import argparse
import csv
import logging
import sys
import time

from common.argtypes import number
from common.errors import TestbedError
from topology.inputs import mobility
from topology.network import Network

log = logging.getLogger("topology.inputs.player")


def play(net: Network, trace: mobility.Trace, tick: float, links_out: str,
         ready: str | None = None) -> int:  # fmt: skip
    """Play `trace` on `net`; returns the number of ticks that came late. `ready`: a file
    created once tick 0 is applied (the caller's sign that the player is running)."""
    robots = net.spec.robots
    scale = net.spec.time_scale
    late = 0
    with open(links_out, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["time", "event", "i", "j"])
        for i, j in sorted(net.links()):
            w.writerow([0, "add", i, j])
        f.flush()
        start = time.monotonic()
        for t in mobility.ticks(trace.end, tick):
            due = start + t / scale
            wait = due - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            elif wait < -tick / scale:
                late += 1
            here = trace.positions(t, robots)
            moves = {k + 1: p for k, p in enumerate(here) if p != net.positions[k]}
            if moves:
                # Saved every tick that moved someone: a feed or `net move` beside the player
                # takes its positions from the state file (Network.refresh).
                added, removed = net.move_many(moves)
                for i, j in sorted(removed):
                    w.writerow([f"{t:g}", "remove", i, j])
                for i, j in sorted(added):
                    w.writerow([f"{t:g}", "add", i, j])
                if added or removed:
                    f.flush()
            if ready is not None:
                open(ready, "w").close()
                ready = None
    net.save()
    return late


def main(argv: list[str] | None = None) -> int:
    """The player's process. Whatever stops it early is one line in its log (`error: ...`)
    and a non-zero exit status, which `net up` reports while it waits for `--ready`."""
    p = argparse.ArgumentParser(prog="python -m topology.inputs.player")
    p.add_argument("name")
    p.add_argument("trace")
    p.add_argument("--tick", type=number(float, "tick", minimum=mobility.MIN_TICK_S),
                   default=0.1, help="emulated seconds between samples")  # fmt: skip
    p.add_argument("--links-out", required=True)
    p.add_argument("--ready", help="a file to create once the first tick is applied")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s player %(message)s")
    try:
        trace = mobility.load(args.trace)
        net = Network.attach(args.name)
    except (mobility.TraceError, TestbedError) as exc:
        log.error("error: %s", exc)
        return 2
    try:
        late = play(net, trace, args.tick, args.links_out, args.ready)
    except OSError as exc:  # links_out, the state file
        where = f"{exc.filename}: " if exc.filename else ""
        log.error("error: %s%s", where, exc.strerror or exc)
        return 1
    except (TestbedError, ValueError) as exc:
        log.error("error: %s", str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
        return 1
    finally:
        net.detach()
    log.info("trace ended at %.3f s emulated; %d late ticks", trace.end, late)
    return 0


if __name__ == "__main__":
    sys.exit(main())
