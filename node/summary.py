"""The robot's summary: the last event of its event log ({"e": "summary", ...}), which
testbed.run.results makes robots/rK.json of. Both robot programs write it, the Python robot
(node.robot.Robot.stop, through `ordered`) and the C++ robot (native/robot/robot.cc's
Robot::stop); its keys, their order and the JSON types of their values are declared here,
once, and tests hold both programs to them (tests/unit/test_robot_summary_keys.py on the
summary event, tests/integration/test_robot_summary_file.py on a run's robots/rK.json).

Counters (`sent`, `received`, `flood`, ...) are objects with a key per kind of thing that
happened (node's COUNTED in that unit test); the rest have fixed keys or are scalars.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

# key -> the JSON types its value may have (Python's, as json.loads gives them back).
FIELDS: Mapping[str, tuple[type, ...]] = {
    "sent": (dict,),  # messages sent, by kind
    "received": (dict,),  # messages received, by kind
    "send_failed": (dict,),  # sends that failed, by kind
    "malformed": (int,),  # messages and floods dropped as malformed
    "flood": (dict,),  # the flooder's counts (node.flood)
    "maps": (dict,),  # map sharing's statistics (node.mapstats)
    "frames": (int,),
    "frames_skipped": (int,),
    "order_timeouts": (int,),
    "inbox_dropped": (int,),
    "plan_ms_median": (float, type(None)),  # None before the first plan
    "cpu_s": (float,),
    "max_rss_mb": (float, type(None)),  # None where /proc does not say
    "busy_s": (dict,),  # seconds of work by part
    "thread_cpu_s": (dict,),  # CPU seconds by thread, "other" for the rest
    "priority": (dict,),  # the scheduling each part with deadlines got
    "lateness": (dict,),  # node.lateness histograms by what was late
    "latency_ms": (dict,),  # percentiles by what was timed (only what was)
    "finished": (bool,),
    "middleware": (str,),
    "messenger": (dict,),  # node.messaging.stats
    "arrivals": (dict,),  # node.messaging.arrivals
    "events_failed": (int,),  # events the event log could not write (node.events)
    "robot_impl": (str,),  # "python" or "cpp"
}
KEYS = tuple(FIELDS)


def problems(summary: Mapping[str, Any]) -> list[str]:
    """What is wrong with a summary as a robot wrote it (its keys in KEYS' order, each value of
    its declared types), one line each; [] when nothing."""
    out = []
    if tuple(summary) != KEYS:
        missing = [k for k in KEYS if k not in summary]
        extra = [k for k in summary if k not in FIELDS]
        if missing or extra:
            out.append(f"keys: missing {missing}, unknown {extra}")
        else:
            out.append("keys: not in node.summary.KEYS' order")
    for key, types in FIELDS.items():
        value = summary.get(key)
        # bool is an int to isinstance: an int field is not a bool, nor a bool field an int.
        if key in summary and (not isinstance(value, types) or (
                isinstance(value, bool) and bool not in types)):  # fmt: skip
            out.append(f"{key}: {type(value).__name__}, not {'/'.join(t.__name__ for t in types)}")
    return out


def ordered(**fields: Any) -> dict[str, Any]:
    """The summary's fields in KEYS' order; ValueError naming what does not fit FIELDS (a
    robot's own mistake, which its tests show)."""
    wrong = problems({k: fields[k] for k in KEYS if k in fields} | fields)
    if wrong:
        raise ValueError("the robot's summary: " + "; ".join(wrong))
    return {k: fields[k] for k in KEYS}
