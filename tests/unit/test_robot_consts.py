"""The C++ robot's shared numbers are the Python robot's (node/constgen.py ->
build/gen/robot_consts.h): the built header is what node.constgen writes now, each of its
literals reads back as the Python value it came from, no native/robot source types one of
them again, and the C++ RobotTimings' formulas on them (`tb-robot --timings SCALE
MAP_PERIOD`) give node.timing.RobotTimings' durations at every time scale, the bounds' own
included; beyond the bounds (common.timescale) both refuse. No root needed; the parts that
run tb-robot are skipped where it was not built.
"""

from __future__ import annotations

import json
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest

from common import timescale
from common.paths import PROJECT_ROOT
from node import constgen
from node.native import TB_ROBOT, unbuilt_reason
from node.timing import RobotTimings
from topology import names

HEADER = Path(PROJECT_ROOT) / "build" / "gen" / "robot_consts.h"
SOURCES = sorted((Path(PROJECT_ROOT) / "native" / "robot").glob("*.[ch]*"))
needs_binary = pytest.mark.skipif(unbuilt_reason() is not None, reason=str(unbuilt_reason()))

# Time scales where a formula's rounding is at stake: 50 / K and 500 / K at a half (20, 40,
# 100, 200: round half to even), just either side of one, the bounds, and irrational ones.
SCALES = [timescale.MIN, 0.02, 0.1, 1 / 3, 0.5, 1.0, 1.5, 2.5, 3.0, 7.0, 9.99, 10.0, 20.0,
          19.999999, 20.000001, 25.0, 40.0, 66.6, 100.0, 200.0, 250.0, 333.3, 999.9,
          timescale.MAX]  # fmt: skip
PERIODS = [1, 7, 10, 50]
PROPERTIES = ["step_order_wait_s", "neighbour_hold_s", "goal_send_timeout_ms",
              "goal_reconnect_min_ms", "goal_reconnect_max_ms", "flood_linger_s"]  # fmt: skip


def literal_value(text: str) -> float:
    """A literal node.constgen wrote, as the number C++ reads (a float: rounded to float32)."""
    if m := re.fullmatch(r"static_cast<float>\((.+)\)", text):
        return float(np.float32(float(m.group(1))))
    if m := re.fullmatch(r"INT64_C\((-?\d+)\)", text):
        return int(m.group(1))
    return float(text) if re.search(r"[.eE]", text) else int(text)


def header_constants(text: str) -> dict[str, float]:
    return {
        m.group(1): literal_value(m.group(2))
        for m in re.finditer(r"^constexpr [\w:]+ (\w+) = (.+?);", text, re.MULTILINE)
    }


def test_each_literal_reads_back_as_its_python_value():
    got = header_constants(constgen.header())
    assert list(got) == [c[1] for c in constgen.constants()]
    for kind, name, value, _ in constgen.constants():
        want = float(np.float32(value)) if kind == "float" else value
        assert got[name] == want, name
        assert isinstance(got[name], float) == (kind in ("float", "double")), name
    arrays = re.findall(r"^constexpr double (\w+)\[\] = \{(.*)\};", constgen.header(), re.M)
    assert {n: tuple(float(v) for v in vals.split(", ")) for n, vals in arrays} == {
        n: tuple(float(v) for v in vals) for n, vals in constgen.ARRAYS.items()
    }


def test_a_whole_number_is_refused_for_a_fraction():
    with pytest.raises(SystemExit, match="not a whole number"):
        constgen.c_value("int", 2.5)


@needs_binary
def test_the_built_header_is_what_constgen_writes_now():
    assert HEADER.read_text() == constgen.header(), "run make setup: build/gen is stale"


@pytest.mark.parametrize("source", SOURCES, ids=lambda p: p.name)
def test_no_source_types_a_shared_number_again(source):
    """A generated name defined with a number of its own (`constexpr int STUCK_FRAMES = 5;`),
    or a timing formula's number beside the time scale, is a second copy that can drift."""
    text = source.read_text()
    names = "|".join(c[1] for c in constgen.constants()) + "|STEP_BOUNDS|MS_BOUNDS"
    defined = rf"\b(?:constexpr|const)\s+[\w:<>]+\s+({names})\b\s*(?:=|\[\]\s*=)\s*[-\d{{]"
    again = re.findall(defined, text)
    assert again == [], f"{source.name} defines {again} itself: use gen:: (robot_consts.h)"
    formulas = re.findall(r"[\d.]+\s*/\s*time_scale|[\d.]+\s*\*\s*[\d.]+\s*/\s*time_scale", text)
    assert formulas == [], f"{source.name} has timing numbers of its own: {formulas}"


def cpp_timings(scale: float, period: int) -> dict:
    out = subprocess.run([str(TB_ROBOT), "--timings", repr(scale), str(period)],
                         capture_output=True, text=True, timeout=30, check=True)  # fmt: skip
    return json.loads(out.stdout)


@needs_binary
@pytest.mark.parametrize("scale", SCALES)
def test_cpp_timings_are_the_python_timings(scale):
    for period in PERIODS:
        py = RobotTimings(time_scale=scale, map_period=period)
        assert cpp_timings(scale, period) == {p: getattr(py, p) for p in PROPERTIES}, (
            scale, period)  # fmt: skip


@needs_binary
@pytest.mark.parametrize("scale", [timescale.MIN * (1 - 1e-9), timescale.MAX * (1 + 1e-9), 0.0,
                                   -1.0, float("inf"), float("nan")])  # fmt: skip
def test_both_refuse_a_time_scale_beyond_the_bounds(scale):
    with pytest.raises(ValueError, match="time scale must be a number in"):
        RobotTimings(time_scale=scale)
    out = subprocess.run([str(TB_ROBOT), "--timings", repr(scale), "10"], capture_output=True,
                         text=True, timeout=30)  # fmt: skip
    assert out.returncode == 2 and out.stdout == "" and len(out.stderr.splitlines()) == 1


def test_time_scale_bounds_are_one_rule():
    assert timescale.valid(timescale.MIN) and timescale.valid(timescale.MAX)
    for bad in (True, "1", None, 0, -1, float("nan"), float("inf"), timescale.MAX + 1e-9):
        assert not timescale.valid(bad) and timescale.refusal(bad) is not None


@needs_binary
def test_cpp_robot_addresses_are_the_address_plans():
    """Robot k's address in the C++ robot (gen:: numbers) is topology.names.robot_addr(k),
    across the third octet's turns; k = 0 is refused as the plan refuses it."""
    for k in (1, 2, 253, 254, 255, 508, 509, 999, 1000):
        out = subprocess.run([str(TB_ROBOT), "--addr", str(k)],
                             capture_output=True, text=True, timeout=30, check=True)  # fmt: skip
        assert out.stdout.strip() == names.robot_addr(k), k
    refused = subprocess.run([str(TB_ROBOT), "--addr", "0"], capture_output=True, text=True,
                             timeout=30)  # fmt: skip
    assert refused.returncode == 2 and "--addr K" in refused.stderr
