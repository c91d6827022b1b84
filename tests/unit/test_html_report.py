"""report.html: the markdown report as one self-contained page."""

from testbed.analysis import htmlreport, report
from testbed.sweep import file as sweepfile
from tests.unit.test_sweep_synthetic import make_sweep


def test_markdown_subset_becomes_html(tmp_path):
    md = "# Title\n\nSome **bold** and `code`.\n\n- one\n- two\n\n| a | b |\n|---|---|\n| 1 | 2 |\n"
    page = htmlreport.to_html(md, tmp_path)
    assert "<h1>Title</h1>" in page and "<strong>bold</strong>" in page
    assert "<code>code</code>" in page and "<li>two</li>" in page
    assert "<th>a</th>" in page and "<td>2</td>" in page and "|" not in page
    assert "&lt;script&gt;" in htmlreport.to_html("<script>x</script>", tmp_path)


def test_report_html_inlines_figures_and_links_every_run(tmp_path):
    spec = sweepfile.SweepSpec.of(robots=(1, 2), comm_range=(5.0,), laser_range=(2.0,), runs=2)
    runs = make_sweep(tmp_path, spec)
    report.write_report(tmp_path, metrics_of=lambda run: None)
    page = (tmp_path / "report.html").read_text()
    assert page.startswith("<!DOCTYPE html>")
    assert 'src="data:image/png;base64,' in page  # Fig. 2, inlined: no server needed
    assert "figures/fig2a.png" not in page
    for run in runs:
        assert f'href="runs/{run.run_id}/result.json"' in page
    assert "The paper" in page and "<table>" in page
