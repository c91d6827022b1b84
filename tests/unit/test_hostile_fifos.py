"""Issue 40, item 3: a FIFO in a results directory is refused or left out, never waited on
(common.boundedfile, the one bounded, regular-files-only, non-blocking reader). Each case
runs under an alarm: a hang fails the test (hostile_dirs.Hung) instead of stopping the suite."""

import pytest

from tests.unit import hostile_dirs as hd


def _run(argv, capsys):
    return hd.within(20, hd.testbed, argv, capsys)


@pytest.mark.parametrize("name", ["medium.json", "relay-lag.bin"])
def test_report_of_a_run_refuses_a_fifo_it_must_read(tmp_path, capsys, name):
    run = hd.run_dir(tmp_path / "s")
    hd.fifo(run / name)
    line = hd.within(20, hd.refused, ["report", run], capsys, name)
    assert "not a regular file" in line


@pytest.mark.parametrize(
    "name", ["aodv/r1.json", "pcaps/r1.pcap", "pcaps/daemons/r1.tcpdump.log", "routing.json"]
)
def test_report_of_a_run_leaves_out_a_fifo_among_its_captures(tmp_path, capsys, name):
    run = hd.with_captures(hd.run_dir(tmp_path / "s"))
    hd.fifo(run / name)
    status, out, err = _run(["report", run], capsys)
    assert status == 0, err
    assert out.startswith("# Run ")


def test_report_of_a_sweep_refuses_a_fifo_sweep_json(tmp_path, capsys):
    sweep = hd.sweep_dir(tmp_path / "sweep")
    hd.fifo(sweep / "sweep.json")
    hd.within(20, hd.refused, ["report", sweep], capsys, "sweep.json", "not a regular file")


def test_report_and_compare_leave_out_a_fifo_result(tmp_path, capsys, caplog):
    a = hd.sweep_dir(tmp_path / "a")
    b = hd.sweep_dir(tmp_path / "b")
    victim = sorted((a / "runs").iterdir())[0]
    hd.fifo(victim / "result.json")
    status, _, err = _run(["report", a], capsys)
    assert status == 0, err
    assert "not a regular file" in caplog.text
    status, out, err = _run(["compare", a, b], capsys)
    assert status == 0, err


@pytest.mark.parametrize("name", ["r1.pcap", "daemons/r1.tcpdump.log"])
def test_metrics_leaves_out_a_fifo(tmp_path, capsys, name):
    d = tmp_path / "cap"
    d.mkdir()
    for k in (1, 2):
        (d / f"r{k}.pcap").write_bytes(hd.EMPTY_PCAP)
    hd.fifo(d / name)
    status, out, err = _run(["metrics", d], capsys)
    assert status == 0, err
    assert "captures" in out


def test_metrics_refuses_a_fifo_network_json(tmp_path, capsys):
    d = tmp_path / "cap"
    d.mkdir()
    (d / "r1.pcap").write_bytes(hd.EMPTY_PCAP)
    hd.fifo(d / "daemons" / "network.json")
    hd.within(20, hd.refused, ["metrics", d], capsys, "network.json", "not a regular file")


@pytest.mark.parametrize("flag", ["--status"])
def test_sweep_status_refuses_a_fifo_sweep_json(tmp_path, capsys, flag):
    sweep = hd.sweep_dir(tmp_path / "sweep")
    hd.fifo(sweep / "sweep.json")
    hd.within(20, hd.refused, ["sweep", flag, sweep], capsys, "sweep.json")


def test_sweep_resume_refuses_a_fifo_sweep_json(tmp_path):
    from common.errors import UsageError
    from testbed.sweep import plan, runner

    sweep = hd.sweep_dir(tmp_path / "sweep")
    hd.fifo(sweep / "sweep.json")
    with pytest.raises(UsageError, match="not a regular file"):
        hd.within(20, plan.other_sweep, sweep, [])
    with pytest.raises(UsageError, match="not a regular file"):
        hd.within(20, runner.wait_for_orphans, sweep)


def test_a_file_read_line_by_line_is_checked_on_the_descriptor_it_was_opened_on(tmp_path):
    """open_text checks the opened descriptor, so a FIFO put in a file's place is refused at
    once (never waited on), and a regular file reads as text."""
    import os

    from common import boundedfile

    fifo, text = tmp_path / "positions.csv", tmp_path / "links.csv"
    os.mkfifo(fifo)
    text.write_text("step,a,b\n0,1,2\n")
    with pytest.raises(boundedfile.Refused) as refused:
        boundedfile.open_text(fifo)
    assert refused.value.kind == "special"
    with pytest.raises(boundedfile.Refused):
        boundedfile.open_text(tmp_path)
    with boundedfile.open_text(text) as f:
        assert f.read().splitlines() == ["step,a,b", "0,1,2"]
