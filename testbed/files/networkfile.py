"""A `net up --capture DIR` network's description, DIR/daemons/network.json, as one type:
`NetworkRecord`, what `testbed metrics DIR` needs of it (testbed.net.movers).

topology.bringup writes the file (the network's spec, its network timers and, once a trace
plays, which trace node is which robot); this is its reader. `read(path)` takes it through the
one bounded reader (common.boundedfile): None when there is none (captures made before the
file, or moved without it), and a file that is there but not one is a ResultError of one line
naming the file and the key, as a bad result.json is: `routing` one of topology.spec.ROUTINGS
(aodv when absent, the only routing before the key), `time_scale` within common.timescale's
bounds (None when absent: delays then stay in wall-clock time).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass

from common import timescale
from testbed.files.resultvalues import NUM, ResultError, get_value, read_json_as
from topology.spec import ROUTINGS

NETWORK_NAME = os.path.join("daemons", "network.json")
DEFAULT_ROUTING = "aodv"  # captures whose file does not say: there was no other routing


def network_path(capture_dir: str | os.PathLike[str]) -> str:
    """Where a capture directory's network.json is."""
    return os.path.join(capture_dir, NETWORK_NAME)


@dataclass(frozen=True)
class NetworkRecord:
    """What the captures of a `net up --capture` network were of."""

    routing: str = DEFAULT_ROUTING
    time_scale: float | None = None  # None: not recorded (delays stay in wall-clock time)


def parse(doc: object) -> NetworkRecord:
    """The NetworkRecord of a network.json's contents; ResultError when it is not one."""
    if not isinstance(doc, Mapping):
        raise ResultError("not a JSON object")
    routing = get_value(doc, "routing", (str,), DEFAULT_ROUTING)
    if routing not in ROUTINGS:
        raise ResultError(f"'routing' is not one of {', '.join(ROUTINGS)}")
    scale = get_value(doc, "time_scale", NUM)
    if scale is not None and not timescale.valid(scale):
        raise ResultError(f"'time_scale': {timescale.refusal(scale)}")
    return NetworkRecord(routing=routing, time_scale=scale)


def read(path: str | os.PathLike[str]) -> NetworkRecord | None:
    """The network.json at `path`; None when there is none; ResultError (one line, naming the
    file) when it is there but unreadable or not one (a FIFO is refused, not waited on)."""
    if not os.path.lexists(path):
        return None
    return read_json_as(path, parse)
