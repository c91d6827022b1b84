"""Property tests of a run directory as `testbed view` reads it back (Hypothesis): whatever
config.json, result.json and the CSV files hold, exactly one of two outcomes: the replay is
built and sane (strict JSON, every number finite and within its bound, counts that agree),
or NotARun with one line saying which file is wrong (exit 2 at the command line)."""

import json
import math
import tempfile
from pathlib import Path

from hypothesis import given, settings
from hypothesis import strategies as st

from testbed.view import replay, served, server
from topology.names import MAX_ROBOTS
from topology.spec import MAX_COORD_M

FUZZ = dict(deadline=None, database=None)

SCALARS = st.one_of(
    st.none(), st.booleans(), st.integers(-(10**20), 10**20), st.floats(), st.text(max_size=12)
)
ANY_JSON = st.recursive(
    SCALARS,
    lambda inner: st.one_of(
        st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=8), inner, max_size=4)
    ),
    max_leaves=12,
)
NUMBERISH = st.one_of(
    st.integers(-3, 2000), st.floats(), st.sampled_from([0, 1, 2, 1e300, -1.0]), SCALARS
)
CONFIGS = st.one_of(
    ANY_JSON,
    st.fixed_dictionaries(
        {"robots": st.one_of(st.integers(1, 3), NUMBERISH)},
        optional={
            "comm_range": NUMBERISH,
            "map_cell": NUMBERISH,
            "map_size": st.one_of(st.lists(NUMBERISH, max_size=3), SCALARS),
            "display_pos": st.one_of(st.lists(NUMBERISH, max_size=3), SCALARS),
            "map": st.one_of(st.text(max_size=30), SCALARS),
        },
    ),
)
CELLS = st.one_of(
    st.floats().map(repr),
    st.integers(-5, 5).map(str),
    st.sampled_from(["nan", "inf", "1e308", "add", "remove", "", "²", "1,2", '"', "\x00"]),
)
CSV_TEXT = st.one_of(
    st.lists(st.lists(CELLS, max_size=8).map(",".join), max_size=5).map("\n".join),
    st.text(max_size=60),
)


def text_of(doc) -> str:
    return json.dumps(doc)  # NaN and Infinity as Python writes them: the reader must cope


def check_sane(data: dict) -> None:
    def refuse(name):
        raise AssertionError(f"{name} in the view's JSON")

    json.loads(server.json_text(data), parse_constant=refuse)
    n = data["robots"]
    assert type(n) is int and 1 <= n <= MAX_ROBOTS
    assert math.isfinite(data["comm_range"]) and 0 <= data["comm_range"] <= MAX_COORD_M
    assert all(math.isfinite(v) and v > 0 for v in data["map_m"])
    assert data["display"] == [] or len(data["display"]) == 2
    for row in data["positions"]:
        assert len(row) == 2 * n
        assert all(math.isfinite(v) and abs(v) <= MAX_COORD_M for v in row)
    for step, added, i, j in data["links"]:
        assert step >= 0 and type(added) is bool and 1 <= i <= n + 1 and 1 <= j <= n + 1
    assert all(0.0 <= c <= 1.0 for c in data["coverage"])
    assert data["steps"] == len(data["positions"]) - 1


def load_or_refuse(files: dict[str, str]) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp) / "run"
        d.mkdir()
        for name, text in files.items():
            (d / name).write_text(text, errors="surrogatepass")
        try:
            data = replay.load(d)
        except replay.NotARun as e:
            assert str(e) and len(str(e).splitlines()) == 1, str(e)
            return
        check_sane(data)
        # The map it names: served by the rule or not at all, never an error.
        picture, why_not = served.map_picture(d, replay.read_config(d)["map"])
        assert picture is None or served.is_png(picture)
        assert why_not is None or len(why_not.splitlines()) == 1


@settings(max_examples=300, **FUZZ)
@given(CONFIGS, st.one_of(ANY_JSON, st.text(max_size=20)))
def test_config_and_result_as_read_back_are_sane_or_refused(config, result):
    result = result if isinstance(result, str) else text_of(result)
    positions = "step,x1,y1\n0,1,2\n"
    load_or_refuse({"config.json": text_of(config), "positions.csv": positions,
                    "result.json": result})  # fmt: skip


@settings(max_examples=250, **FUZZ)
@given(st.integers(1, 3), CSV_TEXT, CSV_TEXT, CSV_TEXT)
def test_the_csv_files_as_read_back_are_sane_or_refused(robots, positions, links, coverage):
    load_or_refuse({"config.json": text_of({"robots": robots, "comm_range": 5.0}),
                    "positions.csv": "step\n" + positions, "links.csv": "h\n" + links,
                    "coverage.csv": "h\n" + coverage})  # fmt: skip


@settings(max_examples=100, **FUZZ)
@given(st.binary(max_size=200), st.binary(max_size=200))
def test_files_that_are_not_text_are_refused(config, positions):
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        (d / "config.json").write_bytes(config)
        (d / "positions.csv").write_bytes(positions)
        try:
            check_sane(replay.load(d))
        except replay.NotARun as e:
            assert len(str(e).splitlines()) == 1
