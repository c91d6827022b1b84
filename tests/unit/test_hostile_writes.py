"""Issue 40, item 1: a results directory from elsewhere cannot make report, compare or
metrics write outside it: a link where a file or a directory is written is replaced or
refused, never followed (common.jsonfile.write_atomic, make_dirs)."""

import os

import pytest

from common import jsonfile
from tests.unit import hostile_dirs as hd


@pytest.fixture
def outside(tmp_path):
    """A directory outside the results directory, with a file a link may point at."""
    d = tmp_path / "outside"
    d.mkdir()
    (d / "precious").write_text("keep me\n")
    return d


def test_write_atomic_replaces_a_link_instead_of_writing_through_it(tmp_path, outside):
    (tmp_path / "summary.md").symlink_to(outside / "precious")
    jsonfile.write_atomic(tmp_path / "summary.md", "new\n")
    assert (outside / "precious").read_text() == "keep me\n"
    assert not (tmp_path / "summary.md").is_symlink()
    assert (tmp_path / "summary.md").read_text() == "new\n"


def test_write_atomic_refuses_a_linked_directory_on_the_way(tmp_path, outside):
    (tmp_path / "figures").symlink_to(outside)
    with pytest.raises(jsonfile.UnsafeWrite, match="figures: a symbolic link"):
        jsonfile.write_atomic(tmp_path / "figures" / "fig2.csv", "x", root=tmp_path)
    with pytest.raises(jsonfile.UnsafeWrite):
        jsonfile.make_dirs(tmp_path / "figures" / "paths", root=tmp_path)
    assert sorted(os.listdir(outside)) == ["precious"]


def test_write_atomic_refuses_a_file_where_a_directory_is_and_a_directory_as_the_file(tmp_path):
    (tmp_path / "figures").write_text("not a directory")
    with pytest.raises(jsonfile.UnsafeWrite, match="not a directory"):
        jsonfile.write_atomic(tmp_path / "figures" / "a.csv", "x", root=tmp_path)
    (tmp_path / "report.md").mkdir()
    with pytest.raises(jsonfile.UnsafeWrite, match="a directory, not a file"):
        jsonfile.write_atomic(tmp_path / "report.md", "x")
    assert sorted(os.listdir(tmp_path)) == ["figures", "report.md"]  # no temporary left


def test_a_sweep_report_replaces_linked_report_files(tmp_path, outside, capsys):
    sweep = hd.sweep_dir(tmp_path / "sweep")
    for name in ("report.md", "report.html"):
        (sweep / name).symlink_to(outside / "precious")
    status, _, err = hd.testbed(["report", sweep], capsys)
    assert status == 0, err
    assert (outside / "precious").read_text() == "keep me\n"
    assert sorted(os.listdir(outside)) == ["precious"]
    assert (sweep / "report.md").read_text().startswith("#")
    assert not (sweep / "report.html").is_symlink()


def test_a_sweep_report_refuses_a_figures_directory_that_is_a_link(tmp_path, outside, capsys):
    sweep = hd.sweep_dir(tmp_path / "sweep")
    (sweep / "figures").symlink_to(outside)
    hd.refused(["report", sweep], capsys, "figures", "symbolic link")
    assert sorted(os.listdir(outside)) == ["precious"]


def test_a_sweep_report_refuses_a_figures_paths_that_is_a_link(tmp_path, outside, capsys):
    sweep = hd.sweep_dir(tmp_path / "sweep")
    (sweep / "figures").mkdir()
    (sweep / "figures" / "paths").symlink_to(outside)
    hd.refused(["report", sweep], capsys, "paths", "symbolic link")
    assert sorted(os.listdir(outside)) == ["precious"]


def test_a_run_report_replaces_a_linked_summary(tmp_path, outside, capsys):
    run = hd.run_dir(tmp_path / "s")
    (run / "summary.md").symlink_to(outside / "precious")
    status, out, err = hd.testbed(["report", run], capsys)
    assert status == 0, err
    assert out.startswith("# Run ")
    assert (outside / "precious").read_text() == "keep me\n"


def test_a_run_directory_that_is_a_link_is_left_out_of_a_sweep(tmp_path, outside, capsys):
    sweep = hd.sweep_dir(tmp_path / "sweep")
    elsewhere = hd.run_dir(outside / "x")
    (elsewhere / "pcaps").mkdir()  # captures: a report would write routing.json beside them
    for k in (1, 2):
        (elsewhere / "pcaps" / f"r{k}.pcap").write_bytes(hd.EMPTY_PCAP)
    (sweep / "runs" / "n09-c5-l2-k1").symlink_to(elsewhere)
    before = hd.snapshot(outside)
    status, _, err = hd.testbed(["report", sweep], capsys)
    assert status == 0, err
    assert hd.snapshot(outside) == before  # no routing.json or anything else written there


def test_compare_out_replaces_a_link(tmp_path, outside, capsys):
    a = hd.sweep_dir(tmp_path / "a")
    b = hd.sweep_dir(tmp_path / "b")
    (tmp_path / "cmp.md").symlink_to(outside / "precious")
    status, _, err = hd.testbed(["compare", a, b, "--out", tmp_path / "cmp.md"], capsys)
    assert status == 0, err
    assert (outside / "precious").read_text() == "keep me\n"


def test_a_sweep_lock_that_is_a_link_is_refused(tmp_path, outside):
    from testbed.sweep import command

    (tmp_path / ".sweep.lock").symlink_to(outside / "precious")
    with pytest.raises(jsonfile.UnsafeWrite.__mro__[1], match=".sweep.lock"):
        command._open_lock(tmp_path)
    assert (outside / "precious").read_text() == "keep me\n"
