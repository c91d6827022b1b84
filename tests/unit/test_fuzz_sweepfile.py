"""Sweep files from anywhere (testbed.sweep.file), fuzzed with Hypothesis: every file ends in
exactly one of two ways. Either it is accepted and sane (at most MAX_RUNS runs, expanded to
exactly the product of its lists, unique run ids, every number finite), or it is refused
with a `UsageError` of one printable line naming the file. Nothing else: no other
exception, no hang, and a grid's size is known before it is expanded.

Inputs: TOML written from generated tables (the real keys with values of every TOML type,
hostile numbers and strings, unknown keys with control characters, huge `runs`), arbitrary
bytes, and mutations of a valid sweep file: 800 examples in all.
"""

import json
import math
import re

import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from common.errors import UsageError
from testbed.sweep import file as sweepfile

BASE = settings(deadline=2000, suppress_health_check=[HealthCheck.too_slow], database=None)

TEXT = st.text(st.characters(blacklist_categories=("Cs",)), max_size=12)  # TOML has no surrogates
SCALARS = st.one_of(
    st.integers(-3, 60),
    st.integers(),
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(0.1, 50),
    st.booleans(),
    st.text(max_size=12),
    st.sampled_from(
        [
            "aodv",
            "oracle",
            "none",
            "paper",
            "ours",
            "corner",
            "spread",
            "empty",
            "veth",
            "ns3-wifi",
            "disc",
            "los",
            "80211b",
            "rfc",
        ]
    ),  # fmt: skip
)
GRID_KEYS = ["robots", "comm_range", "laser_range", "loss_pct", "delay_ms", "coordination",
             "start", "routing", "medium", "runs", "bogus", "bad\nkey", "\x1b[2J"]  # fmt: skip
RUN_KEYS = ["time_scale", "load_limit", "cpu_limit", "routing", "aodv_profile", "max_steps",
            "capture", "range_model", "wall_loss_pct", "medium", "wifi_loss", "wifi_standard",
            "wifi_rate", "seed", "other", "²"]  # fmt: skip


def value(inner=SCALARS):
    keys = st.sampled_from(["1", "2", "²", "x"])
    return st.one_of(inner, st.lists(inner, max_size=6),
                     st.dictionaries(keys, inner, max_size=3))  # fmt: skip


@st.composite
def hostile_tables(draw) -> dict:
    """Any keys, any values: mostly refused, each time for a reason of its own."""
    grid = {}
    for key in ("robots", "comm_range", "laser_range"):
        if draw(st.integers(0, 9)):
            grid[key] = draw(value())
    for key in draw(st.lists(st.sampled_from(GRID_KEYS), max_size=3, unique=True)):
        grid[key] = draw(value())
    if draw(st.booleans()):
        grid["runs"] = draw(st.one_of(st.integers(), st.just(10**15)))
    data = {"grid": grid}
    if draw(st.booleans()):
        keys = draw(st.lists(st.sampled_from(RUN_KEYS), max_size=4, unique=True))
        data["run"] = {k: draw(value()) for k in keys}
    if draw(st.integers(0, 4)) == 0:
        data[draw(st.sampled_from(["description", "extra", "grid"]))] = draw(value())
    return data


@st.composite
def plausible_tables(draw) -> dict:
    """Valid-looking files with a value out of bounds now and then: mostly accepted."""
    small = st.lists(st.integers(1, 6), min_size=1, max_size=4, unique=True)
    grid = {
        "robots": draw(small),
        "comm_range": draw(st.lists(st.floats(0.5, 40), min_size=1, max_size=3, unique=True)),
        "laser_range": draw(
            st.lists(
                st.sampled_from([1.5, 2.0, 4.0, 28.0, 29.0, 31.0, 0.0]),
                min_size=1,
                max_size=2,
                unique=True,
            )
        ),  # fmt: skip
        "runs": draw(st.integers(1, 3)),
    }
    if draw(st.booleans()):
        grid["loss_pct"] = draw(st.lists(st.sampled_from([0, 10, 30, 100, 101, -1]),
                                         min_size=1, max_size=3, unique=True))  # fmt: skip
    if draw(st.booleans()):
        grid["routing"] = draw(st.lists(st.sampled_from(["aodv", "oracle", "none", "olsr"]),
                                        min_size=1, max_size=2, unique=True))  # fmt: skip
    scale = st.floats(0.5, 20)
    run = {"max_steps": draw(st.integers(1, 5000)),
           "time_scale": draw(st.one_of(scale, st.fixed_dictionaries(
               {str(n): scale for n in grid["robots"]})))}  # fmt: skip
    return {"description": draw(TEXT), "grid": grid, "run": run}


def toml_key(k: str) -> str:
    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else json.dumps(k)


def toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return (
            "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
        )
    if isinstance(v, int):
        return str(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    return "{" + ", ".join(f"{toml_key(k)} = {toml_value(x)}" for k, x in v.items()) + "}"


def to_toml(data: dict) -> str:
    top = [f"{toml_key(k)} = {toml_value(v)}" for k, v in data.items() if not isinstance(v, dict)]
    out = top[:]
    for name, table in data.items():
        if isinstance(table, dict):
            out.append(f"[{name}]")
            out += [f"{toml_key(k)} = {toml_value(v)}" for k, v in table.items()]
    return "\n".join(out) + "\n"


@pytest.fixture(scope="module")
def where(tmp_path_factory):
    return tmp_path_factory.mktemp("fuzz")


def check(tmp_path, content: bytes) -> None:
    """The property: accepted and sane, or one line of refusal."""
    f = tmp_path / "sweep.toml"
    f.write_bytes(content)
    try:
        spec = sweepfile.load(f)
    except UsageError as exc:
        msg = str(exc)
        assert msg.startswith(f"sweep file {f}") and msg.isprintable(), msg
        event("refused")
        return
    event("accepted")
    dims = [values for _, values in spec.grid]
    total = math.prod(len(d) for d in dims) * spec.runs
    assert total <= sweepfile.MAX_RUNS
    runs = sweepfile.expand(spec)
    assert len(runs) == total == len({r.run_id for r in runs})
    for r in runs:
        c = r.config
        for x in (c.comm_range, c.laser_range, c.loss_pct, c.delay_ms, c.time_scale):
            assert math.isfinite(x) and x >= 0
        assert 1 <= c.robots <= 50
    assert spec.cpu_limit is None or (math.isfinite(spec.cpu_limit) and spec.cpu_limit > 0)


@settings(BASE, max_examples=300)
@given(st.one_of(hostile_tables(), plausible_tables()))
def test_generated_sweep_files(where, data):
    check(where, to_toml(data).encode())


@settings(BASE, max_examples=250)
@given(st.binary(max_size=300))
def test_arbitrary_bytes(where, content):
    check(where, content)


VALID = """\
[grid]
robots = [1, 2]
comm_range = [5, 20]
laser_range = [2.0]
runs = 2

[run]
time_scale = { 1 = 5.0, 2 = 4.0 }
max_steps = 500
"""


@settings(BASE, max_examples=250)
@given(st.data())
def test_mutated_valid_sweep_files(where, data):
    text = VALID
    for _ in range(data.draw(st.integers(1, 3))):
        at = data.draw(st.integers(0, len(text)))
        cut = data.draw(st.integers(0, 4))
        text = text[:at] + data.draw(st.text(max_size=8)) + text[at + cut :]
    check(where, text.encode(errors="surrogatepass"))
