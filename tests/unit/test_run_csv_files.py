"""A run's CSV files (testbed.files.csvfiles): what RunFiles writes reads back through the
one reader, and a row that is not what runs write is refused naming its line."""

import os

import pytest

from common import boundedfile
from testbed.files import csvfiles
from testbed.files.csvfiles import CsvError, LinkChange
from testbed.run.files import RunFiles


def _run(tmp_path):
    with RunFiles(str(tmp_path), robots=2) as f:
        f.links(0, added=[(1, 2), (2, 3)])
        f.positions(0, [(0.0, 1.0), (2.5, -3.25)])
        f.coverage(0, 0.1)
        f.links(1, added=[(1, 3)], removed=[(1, 2)])
        f.positions(1, [(0.5, 1.0), (2.5, -3.0)])
        f.coverage(1, 0.25)


def test_what_a_run_writes_reads_back(tmp_path):
    _run(tmp_path)
    assert csvfiles.read_links(tmp_path) == [
        LinkChange(0, True, 1, 2), LinkChange(0, True, 2, 3),
        LinkChange(1, False, 1, 2), LinkChange(1, True, 1, 3),
    ]  # fmt: skip
    positions = csvfiles.rows(tmp_path / "positions.csv", csvfiles.position_rows(2))
    assert positions == [[0.0, 1.0, 2.5, -3.25], [0.5, 1.0, 2.5, -3.0]]
    assert csvfiles.rows(tmp_path / "coverage.csv", csvfiles.coverage_row) == [0.1, 0.25]
    header = (tmp_path / "positions.csv").read_text().splitlines()[0]
    assert header.split(",") == csvfiles.positions_header(2) == ["step", "x1", "y1", "x2", "y2"]


@pytest.mark.parametrize(
    ("text", "line", "why"),
    [
        ("step,event,i,j\n0,add,1,2\n0,join,1,2\n", 3, "not step,add|remove,i,j"),
        ("step,event,i,j\n0,add,1,1\n", 2, "a link of robot 1 to itself"),
        ("step,event,i,j\n0,add,1,9\n", 2, "'9' is not a whole number in 1..3"),
        ("step,event,i,j\n-1,add,1,2\n", 2, "'-1' is not a whole number"),
    ],
)
def test_a_bad_link_row_is_refused_naming_its_line(tmp_path, text, line, why):
    (tmp_path / "links.csv").write_text(text)
    with pytest.raises(CsvError) as e:
        csvfiles.rows(tmp_path / "links.csv", csvfiles.link_rows(2, 5))
    assert e.value.line == line and e.value.why.startswith(why)


@pytest.mark.parametrize(
    ("rows", "why"),
    [
        (["0,1,2,3,4", "2,1,2,3,4"], "step '2', not 1"),
        (["0,1,2,3"], "4 columns, not 5"),
        (["0,nan,2,3,4"], "'nan' is not a number"),
        (["0,1e12,2,3,4"], "'1e12' is not a number"),
    ],
)
def test_a_bad_position_row_is_refused(tmp_path, rows, why):
    (tmp_path / "positions.csv").write_text("\n".join(["step,x1,y1,x2,y2", *rows]) + "\n")
    with pytest.raises(CsvError, match=why):
        csvfiles.rows(tmp_path / "positions.csv", csvfiles.position_rows(2))


def test_a_missing_or_special_file_is_refused(tmp_path):
    with pytest.raises(boundedfile.Refused):
        csvfiles.read_links(tmp_path)
    os.mkfifo(tmp_path / "links.csv")
    with pytest.raises(boundedfile.Refused) as r:
        csvfiles.read_links(tmp_path)
    assert r.value.kind == "special"


def test_the_header_of_positions_names_the_robots():
    assert csvfiles.position_columns(csvfiles.positions_header(3)) == [1, 2, 3]
    assert csvfiles.position_columns(["step", "x1001", "y1001"]) == [1001]  # the display
    for bad in ([], ["t", "x1", "y1"], ["step", "x1"], ["step", "x1", "y2"],
                ["step", "x1002", "y1002"]):  # fmt: skip
        with pytest.raises(ValueError):
            csvfiles.position_columns(bad)
    assert csvfiles.coordinate("-2.5") == -2.5
    for bad in ("inf", "nan", "1e8", "x"):
        with pytest.raises(ValueError):
            csvfiles.coordinate(bad)
