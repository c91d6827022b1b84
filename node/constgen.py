"""The C++ robot's shared numbers, written from the Python robot: `python -m node.constgen
HEADER`.

`make` runs it before it compiles build/tb-robot (and its sanitizer builds): HEADER
(build/gen/robot_consts.h) holds every number the two robots must agree on that is not part
of the command line (node.argsgen writes those into build/gen/node_args.h), each read here
from the one Python place that defines it, so that a change there reaches the compiled robot
at its next build instead of drifting:

- the timings' constants (node.timing) and the time scale's bounds (common.timescale): the
  C++ RobotTimings (native/robot/robot.h) keeps node.timing.RobotTimings' formulas and takes
  their numbers from here (`tb-robot --timings SCALE MAP_PERIOD` prints its results, which
  tests/unit/test_robot_consts.py holds equal to node.timing's across time scales);
- the robot's rules: RobotConfig's full_period, reach_steps, goal_fresh_steps and
  planner_factor, STUCK_FRAMES and INBOX_LIMIT (node.robotcore), the waypoint tolerance
  (node.motion), the log-odds (node.grid.LogOdds), the ternary cell values and the largest map;
- the wire: the flood's TTL, duplicate window, sequence window and socket buffers
  (node.flood), the flood and map headers' sizes, kinds and neighbour bound, the messages'
  nesting bound (node.wire), the body link's message sizes (node.body);
- the laser's table constants (node.rays), the lateness histograms' bounds (node.lateness),
  when a message arrived late (node.messaging.arrivals), the deadline priority (common.sched);
- the robots' address plan (topology.names: `tb-robot --addr K` prints robot K's address,
  which the test holds equal to topology.names.robot_addr).

tests/unit/test_robot_consts.py holds the built header to these values and the C++ sources
to using it. The file is rewritten only when its text changes, so that make rebuilds tb-robot
only then.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from common import sched, timescale
from common.cliterals import c_real, write_header
from node import body, flood, grid, lateness, messaging, motion, rays, robotcore, timing, wire
from node.messaging import arrivals
from topology import names

# (C++ type, name, value, where it comes from), in the header's order.
Const = tuple[str, str, object, str]


def constants() -> list[Const]:
    """Every constant of the header."""
    cfg = robotcore.RobotConfig(robot=1, robots=1)
    odds = grid.LogOdds()
    # fmt: off
    return [
        ("double", "STEP_S", timing.STEP_S, "node.timing"),
        ("double", "NEIGHBOUR_HOLD_MAP_PERIODS", timing.NEIGHBOUR_HOLD_MAP_PERIODS, "node.timing"),
        ("int", "GOAL_SEND_TIMEOUT_EMULATED_MS", timing.GOAL_SEND_TIMEOUT_EMULATED_MS,
         "node.timing"),
        ("int", "GOAL_SEND_TIMEOUT_MIN_MS", timing.GOAL_SEND_TIMEOUT_MIN_MS, "node.timing"),
        ("int", "GOAL_RECONNECT_MIN_EMULATED_MS", timing.GOAL_RECONNECT_MIN_EMULATED_MS,
         "node.timing"),
        ("int", "GOAL_RECONNECT_MAX_EMULATED_MS", timing.GOAL_RECONNECT_MAX_EMULATED_MS,
         "node.timing"),
        ("int", "NNG_MIN_MS", timing.NNG_MIN_MS, "node.timing"),
        ("double", "FLOOD_LINGER_MAX_S", timing.FLOOD_LINGER_MAX_S, "node.timing"),
        ("double", "FLOOD_LINGER_EMULATED_S", timing.FLOOD_LINGER_EMULATED_S, "node.timing"),
        ("double", "STEP_ORDER_WAIT_STEPS", timing.STEP_ORDER_WAIT_STEPS, "node.timing"),
        ("double", "TIME_SCALE_MIN", timescale.MIN, "common.timescale.MIN"),
        ("double", "TIME_SCALE_MAX", timescale.MAX, "common.timescale.MAX"),
        ("int", "FULL_PERIOD", cfg.full_period, "RobotConfig.full_period"),
        ("int", "REACH_STEPS", cfg.reach_steps, "RobotConfig.reach_steps"),
        ("int", "GOAL_FRESH_STEPS", cfg.goal_fresh_steps, "RobotConfig.goal_fresh_steps"),
        ("int", "PLANNER_FACTOR", cfg.planner_factor, "RobotConfig.planner_factor"),
        ("int", "STUCK_FRAMES", robotcore.STUCK_FRAMES, "node.robotcore"),
        ("size_t", "INBOX_LIMIT", robotcore.INBOX_LIMIT, "node.robotcore"),
        ("double", "WAYPOINT_TOL_M", motion.WAYPOINT_TOL_M, "node.motion"),
        ("double", "WAYPOINT_TOL_SPEEDS", motion.WAYPOINT_TOL_SPEEDS, "node.motion"),
        ("float", "L_FREE", odds.l_free, "node.grid.LogOdds.l_free"),
        ("float", "L_OCC", odds.l_occ, "node.grid.LogOdds.l_occ"),
        ("float", "L_MAX", odds.l_max, "node.grid.LogOdds.l_max"),
        ("float", "THRESHOLD", odds.threshold, "node.grid.LogOdds.threshold"),
        ("float", "MERGED", odds.merged, "node.grid.LogOdds.merged"),
        ("uint8_t", "UNKNOWN", grid.UNKNOWN, "node.grid"),
        ("uint8_t", "FREE", grid.FREE, "node.grid"),
        ("uint8_t", "OCC", grid.OCC, "node.grid"),
        ("int64_t", "MAX_CELLS", grid.MAX_CELLS, "node.grid"),
        ("uint8_t", "FLOOD_TTL", flood.TTL, "node.flood.TTL"),
        ("int64_t", "WINDOW", flood.WINDOW, "node.flood"),
        ("int64_t", "SEQ_WINDOW", flood.SEQ_WINDOW, "node.flood"),
        ("int", "FLOOD_SOCKET_BUFFER", flood.SOCKET_BUFFER, "node.flood.SOCKET_BUFFER"),
        ("uint8_t", "KIND_MAP", wire.KIND_MAP, "node.wire"),
        ("uint8_t", "KIND_BEACON", wire.KIND_BEACON, "node.wire"),
        ("size_t", "MAX_NEIGHBOURS", wire.MAX_NEIGHBOURS, "node.wire"),
        ("size_t", "FLOOD_HDR", wire._HDR.size, "node.wire._HDR.size"),
        ("size_t", "FLOOD_FIXED", wire._FIXED, "node.wire._FIXED: header, sender, neighbour count"),
        ("size_t", "MAP_HDR", wire._MAP.size, "node.wire._MAP.size"),
        ("int", "MAX_DEPTH", wire.MAX_DEPTH, "node.wire"),
        ("size_t", "BODY_HELLO", body._HELLO.size, "node.body._HELLO.size"),
        ("size_t", "BODY_FRAME", body._FRAME.size, "node.body._FRAME.size: without the ranges"),
        ("size_t", "BODY_CMD", body._CMD.size, "node.body._CMD.size"),
        ("size_t", "BODY_DONE", body._DONE.size, "node.body._DONE.size"),
        ("int", "BIAS", rays._BIAS, "node.rays._BIAS"),
        ("int", "FRAC", rays._FRAC, "node.rays._FRAC"),
        ("int", "BUCKETS", rays._BUCKETS, "node.rays._BUCKETS"),
        ("int64_t", "TABLE_BUDGET_BYTES", rays._TABLE_BUDGET_BYTES, "node.rays"),
        ("int64_t", "LATE_STEPS", arrivals.LATE_STEPS, "node.messaging.arrivals"),
        ("int", "SEND_QUEUE", messaging.SEND_QUEUE, "node.messaging"),
        ("int", "DEADLINE_RT", sched.DEADLINE_PRIORITY[0], "common.sched.DEADLINE_PRIORITY"),
        ("int", "DEADLINE_NICE", sched.DEADLINE_PRIORITY[1], "common.sched.DEADLINE_PRIORITY"),
        ("int", "NET_OCTET_A", names.NET_OCTETS[0], "topology.names.NET_OCTETS"),
        ("int", "NET_OCTET_B", names.NET_OCTETS[1], "topology.names.NET_OCTETS"),
        ("int", "ADDRS_PER_OCTET", names.ADDRS_PER_OCTET, "topology.names"),
    ]
    # fmt: on


# The lateness histograms' bounds (node.lateness), as arrays.
ARRAYS = {"STEP_BOUNDS": lateness.STEP_BOUNDS, "MS_BOUNDS": lateness.MS_BOUNDS}


def c_value(kind: str, value: object) -> str:
    """`value` as a C++ literal of `kind` that reads back as the Python value."""
    if kind == "float":  # as numpy's np.float32(v): the double, rounded to float once
        return f"static_cast<float>({c_real(float(value))})"  # type: ignore[arg-type]
    if kind == "double":
        return c_real(float(value))  # type: ignore[arg-type]
    number = int(value)  # type: ignore[call-overload]
    if isinstance(value, float | np.floating) or number != value:
        raise SystemExit(f"node.constgen: {value!r} is not a whole number for a {kind}")
    return f"INT64_C({number})" if kind == "int64_t" else str(number)


def header() -> str:
    """The header's text."""
    lines = [
        "// Generated by node/constgen.py from the Python robot when tb-robot is built: do not",
        "// edit; change the Python constant named beside each (node.constgen says where).",
        "#pragma once",
        "",
        "#include <cstddef>",
        "#include <cstdint>",
        "",
        "namespace tb::gen {",
        "",
    ]
    for kind, name, value, source in constants():
        lines.append(f"constexpr {kind} {name} = {c_value(kind, value)};  // {source}")
    lines.append("")
    for name, values in ARRAYS.items():
        lines.append(
            f"constexpr double {name}[] = {{{', '.join(c_real(v) for v in values)}}};"
            "  // node.lateness"
        )
    lines += ["", "}  // namespace tb::gen", ""]
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    """Write the header to argv[0] (only if its text changed)."""
    if len(argv) != 1 or argv[0].startswith("-"):
        sys.stderr.write("usage: python -m node.constgen HEADER\n")
        return 2
    path, text = Path(argv[0]), header()
    write_header(path, text)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
