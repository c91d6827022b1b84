"""Issue 40, item 2: report.html takes no markup from the sweep's files: run directory names
in links, strings from result.json (one line), and only the report's own figures inlined."""

import base64
import json
import re

import pytest

from testbed.analysis import htmlreport
from testbed.files.resultfile import RunResult
from testbed.files.resultvalues import one_line
from tests.unit import hostile_dirs as hd

EVIL_NAME = 'x" onmouseover="alert(1)"'


@pytest.fixture
def secret_png(tmp_path_factory):
    """A local PNG outside every results directory, which no report may inline."""
    path = tmp_path_factory.mktemp("private") / "secret.png"
    path.write_bytes(hd.png_bytes(b"private data"))
    return path


def _report(sweep, capsys) -> str:
    status, _, err = hd.testbed(["report", sweep], capsys)
    assert status == 0, err
    return (sweep / "report.html").read_text()


def test_a_run_directory_name_is_escaped_in_its_links(tmp_path, capsys):
    sweep = hd.sweep_dir(tmp_path / "sweep")
    first = sorted((sweep / "runs").iterdir())[0]
    first.rename(first.parent / EVIL_NAME)
    page = _report(sweep, capsys)
    assert 'onmouseover="alert(1)"' not in page
    assert "x%22%20onmouseover%3D%22alert%281%29%22/result.json" in page
    for href in re.findall(r'href="([^"]*)"', page):
        assert '"' not in href and "<" not in href


def test_a_fidelity_reason_cannot_add_markdown_lines_or_images(tmp_path, secret_png, capsys):
    sweep = hd.sweep_dir(tmp_path / "sweep")
    reason = f'late\n\n![a](x" onerror="alert(1))\n\n![leak]({secret_png})\n'
    for run in (sweep / "runs").iterdir():
        hd.edit_result(run, lambda d: d.update(fidelity={"ok": False, "reason": reason}))
    status, _, err = hd.testbed(["report", sweep, "--include-unfaithful"], capsys)
    assert status == 0, err
    page = (sweep / "report.html").read_text()
    md = (sweep / "report.md").read_text()
    assert "\n![a]" not in md and "\n![leak]" not in md  # one line: no line of its own
    assert not re.findall(r"<[^>]*onerror", page)  # text, never an attribute of a tag
    assert base64.b64encode(secret_png.read_bytes()).decode() not in page
    assert re.findall(r'<img [^>]*src="([^"]*)"', page)  # its own figures are inlined
    assert all(s.startswith("data:image/png;base64,") for s in re.findall(r'src="([^"]*)"', page))


def test_only_the_reports_own_figures_are_inlined(tmp_path, secret_png):
    (tmp_path / "figures").mkdir()
    own = tmp_path / "figures" / "fig2a.png"
    own.write_bytes(secret_png.read_bytes())
    (tmp_path / "figures" / "out.png").symlink_to(secret_png)
    md = f"# R\n\n![f](figures/fig2a.png)\n\n![s]({secret_png})\n\n![l](figures/out.png)\n"
    md += '\n![q](figures/a.png" onerror="x)\n'
    page = htmlreport.to_html(md, tmp_path)
    assert page.count("<img ") == 1  # fig2a only: the absolute path and the link are text
    assert f"![s]({secret_png})" in page
    assert not re.findall(r"<[^>]*onerror", page)


def test_strings_from_result_json_are_one_line():
    doc = json.loads(json.dumps(hd_result()))
    doc["status_detail"] = "bad\n# heading\x1b[2J"
    doc["fidelity"] = {"ok": False, "reason": "a\nb", "network": {"ok": True, "reason": "\r"}}
    r = RunResult.from_json(doc)
    assert r.status_detail == "bad\\n# heading\\x1b[2J"
    assert r.fidelity_reason == "a\\nb" and r.network_reason == "\\r"
    assert one_line("x" * 600).endswith("…") and len(one_line("x" * 600)) == 500


def hd_result():
    from testbed.sweep import file as sweepfile
    from tests.unit.test_sweep_synthetic import result_doc

    spec = sweepfile.SweepSpec.of(robots=(1,), comm_range=(5.0,), laser_range=(2.0,), runs=1)
    return result_doc(sweepfile.expand(spec)[0].config, [10], 10)
