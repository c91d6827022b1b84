"""The time scale's bounds, written once: emulated time runs K times as fast as the wall
clock, K in [MIN, MAX] (a step of 10 s to one of 100 microseconds, node.timing.STEP_S being
0.1 s).

Every layer that takes a time scale checks it with `valid` (or `refusal` for the one-line
reason): the robot's command line (node.launch.NodeArgs, and so `testbed run`'s option and
the C++ robot through build/gen/node_args.h), the robot's timings (node.timing), a network's
description (topology.spec) and its timers (topology.kernel.nettimers), the result.json
checks (testbed.files.resultcheck) and the metrics a `net` run left (testbed.net.movers);
the C++ robot's own timings (native/robot, `tb-robot --timings`) take MIN and MAX from
build/gen/robot_consts.h (node.constgen). It lives in common/ because topology/, below node/,
checks it too. The AODV daemon (`python -m aodv --time-scale`, aodv.params) keeps its own
rule, any number above 0, which its compiled twin (native/aodv) is held equal to.
"""

from __future__ import annotations

import math

MIN = 0.01  # a step of 10 wall seconds
MAX = 1000.0  # a step of 100 wall microseconds


def valid(value: object) -> bool:
    """Whether `value` is a time scale: a real number (not a bool), MIN <= value <= MAX (so
    finite and positive)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return False
    return math.isfinite(value) and MIN <= value <= MAX


def refusal(value: object) -> str | None:
    """Why `value` is not a time scale (one line), or None when it is."""
    return (
        None
        if valid(value)
        else f"time scale must be a number in [{MIN:g}, {MAX:g}], not {value!r}"
    )
