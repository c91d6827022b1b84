"""Sweep files: validation (one-line errors naming the key), expansion, run ids and seeds."""

import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from common.errors import UsageError
from testbed.sweep import file as sweepfile
from testbed.sweep.rundir import plan_dict

REPO = Path(__file__).resolve().parents[2]
EXPERIMENTS = REPO / "testbed" / "experiments"

GOOD = """
[grid]
robots = [1, 2]
comm_range = [5, 20]
laser_range = [2.0]
runs = 2

[run]
time_scale = 4
capture = true
"""


def parse(text: str):
    return sweepfile.parse(tomllib.loads(text), "s.toml")


@pytest.mark.parametrize(
    "text, key",
    [
        (GOOD + "\nfoo = 1\n", "run.foo"),
        ("bogus = 1\n" + GOOD, "bogus"),
        (GOOD.replace("runs = 2", "runs = 2\nteams = [1]"), "grid.teams"),
        (GOOD.replace("robots = [1, 2]", "robots = []"), "grid.robots"),
        (GOOD.replace("comm_range = [5, 20]", "comm_range = []"), "grid.comm_range"),
        (GOOD.replace("laser_range = [2.0]", ""), "grid.laser_range"),
        (GOOD.replace("robots = [1, 2]", 'robots = "1-10"'), "grid.robots"),
        (GOOD.replace("robots = [1, 2]", "robots = [1, 2.5]"), "grid.robots"),
        (GOOD.replace("robots = [1, 2]", "robots = [true]"), "grid.robots"),
        (GOOD.replace("robots = [1, 2]", "robots = [0, 2]"), "grid.robots"),
        (GOOD.replace("robots = [1, 2]", "robots = [2, 2]"), "grid.robots"),
        (GOOD.replace("comm_range = [5, 20]", 'comm_range = ["far"]'), "grid.comm_range"),
        (GOOD.replace("comm_range = [5, 20]", "comm_range = [-5]"), "grid.comm_range"),
        (GOOD.replace("runs = 2", "runs = 2\nloss_pct = [120]"), "grid.loss_pct"),
        (GOOD.replace("runs = 2", "runs = 2\ndelay_ms = []"), "grid.delay_ms"),
        (GOOD.replace("runs = 2", "runs = 0"), "grid.runs"),
        (GOOD.replace("runs = 2", "runs = 1.5"), "grid.runs"),
        (GOOD.replace("time_scale = 4", 'time_scale = "fast"'), "run.time_scale"),
        (GOOD.replace("time_scale = 4", "time_scale = 0"), "run.time_scale"),
        (GOOD.replace("time_scale = 4", "time_scale = { 1 = 8 }"), "run.time_scale"),
        (GOOD.replace("time_scale = 4", "time_scale = { 1 = 8, 2 = -1 }"), "run.time_scale.2"),
        (GOOD.replace("time_scale = 4", "time_scale = { 1 = 8, two = 4 }"), "run.time_scale.two"),
        (GOOD + "load_limit = 0\n", "run.load_limit"),
        (GOOD + "cpu_limit = 0\n", "run.cpu_limit"),
        (GOOD + "cpu_limit = -1.5\n", "run.cpu_limit"),
        (GOOD + "cpu_limit = nan\n", "run.cpu_limit"),
        (GOOD + "cpu_limit = inf\n", "run.cpu_limit"),
        (GOOD + "load_limit = nan\n", "run.load_limit"),
        (GOOD + 'cpu_limit = "2"\n', "run.cpu_limit"),
        (GOOD + "cpu_limit = true\n", "run.cpu_limit"),
        (GOOD.replace("capture = true", 'capture = "yes"'), "run.capture"),
        (GOOD + 'routing = "olsr"\n', "run.routing"),
        (GOOD + "max_steps = true\n", "run.max_steps"),
        (GOOD + "seed = 1.5\n", "run.seed"),
        ("description = 3\n" + GOOD, "description"),
        ("[run]\ntime_scale = 1\n", "grid"),
        ("grid = 3\n", "grid"),
    ],
)
def test_bad_sweep_file_names_the_key(text, key):
    with pytest.raises(UsageError) as e:
        parse(text)
    msg = str(e.value)
    assert "\n" not in msg
    assert msg.startswith(f"sweep file s.toml: {key}:"), msg
    assert e.value.exit_status == 2


def test_defaults_and_types():
    spec = parse(GOOD)
    assert spec.values("robots") == (1, 2)
    ranges = spec.values("comm_range")
    assert ranges == (5.0, 20.0) and all(isinstance(x, float) for x in ranges)
    assert spec.values("loss_pct") == (0.0,) and spec.values("delay_ms") == (0.0,)
    assert not spec.varies("loss_pct") and spec.varies("robots")
    base = spec.base
    assert base.time_scale == 4.0 and base.capture is True and base.routing == "aodv"
    assert base.max_steps == 3000 and spec.runs == 2


def test_invalid_toml_and_missing_file(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[grid\nrobots = [1]\n")
    with pytest.raises(UsageError, match="invalid TOML"):
        sweepfile.load(bad)
    with pytest.raises(UsageError, match="cannot read"):
        sweepfile.load(tmp_path / "absent.toml")


def test_relative_map_path_is_relative_to_the_file(tmp_path):
    f = tmp_path / "s.toml"
    f.write_text(GOOD + 'map = "maps/office.png"\n')
    assert sweepfile.load(f).base.map == str(tmp_path / "maps" / "office.png")


@pytest.mark.parametrize(
    "name, n_runs",
    [
        ("paper", 10 * 4 * 2 * 3),
        ("short", 6),
        ("impairments", 2 * 3 * 2 * 3),
        ("protocols", 3 * 3 * 4 * 2 * 3),
        ("protocols-short", 4 * 2),
        ("media", 3 * 2 * 2 * 5),
        ("media-protocols", 2 * 3 * 2 * 3),
        ("media-rise", 6 * 2 * 3),
        ("media-rise-slow", 6 * 2 * 3),
    ],  # fmt: skip
)
def test_profiles_load(name, n_runs):
    spec = sweepfile.load(EXPERIMENTS / f"{name}.toml")
    runs = sweepfile.expand(spec)
    assert len(runs) == n_runs
    assert len({r.run_id for r in runs}) == n_runs
    assert spec.base.capture


def test_paper_profile_is_the_papers_grid():
    spec = sweepfile.load(EXPERIMENTS / "paper.toml")
    assert spec.values("robots") == tuple(range(1, 11))
    assert spec.values("comm_range") == (5.0, 10.0, 15.0, 20.0)
    assert spec.values("laser_range") == (2.0, 1.5)
    assert spec.runs == 3


def test_media_profiles_are_issue_22s_grids():
    media = sweepfile.load(EXPERIMENTS / "media.toml")
    grid = dict(media.grid)
    assert (grid["robots"], grid["comm_range"], grid["laser_range"]) == (
        (2, 5, 10),
        (5.0, 20.0),
        (2.0,),
    )
    assert (grid["medium"], media.base.routing, media.runs) == (("veth", "ns3-wifi"), "aodv", 5)
    protos = dict(sweepfile.load(EXPERIMENTS / "media-protocols.toml").grid)
    assert (protos["robots"], protos["routing"]) == ((10,), ("aodv", "babel", "batman"))
    assert protos["medium"] == ("veth", "ns3-wifi")
    rise = sweepfile.load(EXPERIMENTS / "media-rise.toml")
    slow = sweepfile.load(EXPERIMENTS / "media-rise-slow.toml")
    assert rise.values("robots") == (1, 2, 4, 6, 8, 10)
    assert rise.values("comm_range") == (5.0, 20.0)
    assert (rise.base.medium, rise.base.wifi_standard, rise.runs) == ("ns3-wifi", "80211a", 3)
    assert (slow.base.wifi_standard, slow.base.wifi_rate) == ("80211b", "DsssRate1Mbps")
    # the slow channel's runs are the fast one's, point for point (ids, seeds, time scales)
    fast_runs, slow_runs = sweepfile.expand(rise), sweepfile.expand(slow)
    assert [(r.run_id, r.config.seed, r.config.time_scale) for r in fast_runs] == [
        (r.run_id, r.config.seed, r.config.time_scale) for r in slow_runs
    ]


def test_run_ids_and_seeds_are_stable_and_distinct():
    spec = parse(GOOD.replace("runs = 2", "runs = 2\nloss_pct = [0, 10]\ndelay_ms = [0, 50]"))
    a, b = sweepfile.expand(spec), sweepfile.expand(spec)
    assert [r.run_id for r in a] == [r.run_id for r in b]
    assert [r.config for r in a] == [r.config for r in b]
    assert len({r.run_id for r in a}) == len(a)
    assert len({r.config.seed for r in a}) == len(a)
    ids = {r.run_id for r in a}
    assert "n01-c5-l2-k1" in ids and "n02-c20-l2-p10-d50-k2" in ids
    # The id and seed depend on the point and index only: a bigger grid keeps them.
    bigger = parse(
        GOOD.replace("robots = [1, 2]", "robots = [1, 2, 3]").replace("runs = 2", "runs = 3")
    )
    small = {r.run_id: r.config.seed for r in sweepfile.expand(parse(GOOD))}
    big = {r.run_id: r.config.seed for r in sweepfile.expand(bigger)}
    assert all(big[k] == v for k, v in small.items())
    # ...and on the file's base seed.
    other = {r.run_id: r.config.seed for r in sweepfile.expand(parse(GOOD + "seed = 7\n"))}
    assert set(other) == set(small) and all(other[k] != small[k] for k in small)


def test_expansion_covers_every_point_once_before_repeating():
    runs = sweepfile.expand(parse(GOOD))
    assert [r.index for r in runs] == [1, 1, 1, 1, 2, 2, 2, 2]
    first = runs[0].config
    assert set(plan_dict(first)) == {
        "robots", "comm_range", "laser_range", "seed", "time_scale", "routing", "map",
        "loss_pct", "delay_ms", "capture", "max_steps", "coordination", "start",
    }  # fmt: skip
    assert (first.coordination, first.start) == ("ours", "corner")


def _refused_line(tmp_path, text: str) -> str:
    """`testbed sweep` of a file holding `text`: exit 2, one line on stderr (returned), and
    no output directory."""
    f = tmp_path / "s.toml"
    f.write_text(text)
    r = subprocess.run(
        [sys.executable, "-m", "testbed.sweep.command", str(f), "--out", str(tmp_path / "out")],
        capture_output=True,
        text=True,
        cwd=REPO,
    )
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert not (tmp_path / "out").exists()
    return lines[0]


def test_cli_bad_file_one_line_exit_2(tmp_path):
    assert "grid.robots" in _refused_line(tmp_path, GOOD.replace("robots = [1, 2]", "robots = []"))


def test_cpu_limit_is_a_number_of_cores_recorded_with_the_spec():
    spec = parse(GOOD + "cpu_limit = 1.8\nload_limit = 40\n")
    assert spec.cpu_limit == 1.8 and spec.load_limit == 40.0
    assert spec.to_dict()["cpu_limit"] == 1.8
    assert parse(GOOD + "cpu_limit = 2\n").cpu_limit == 2.0
    assert parse(GOOD).cpu_limit is None


def test_cli_bad_cpu_limit_one_line_exit_2(tmp_path):
    line = _refused_line(tmp_path, GOOD + "cpu_limit = nan\n")
    assert "run.cpu_limit" in line and "finite" in line, line


def test_time_scale_per_team_size():
    spec = parse(
        GOOD.replace("time_scale = 4", "time_scale = { 2 = 6, 1 = 12.5 }\nload_limit = 40")
    )
    assert spec.time_scale_by_robots == ((1, 12.5), (2, 6.0)) and spec.load_limit == 40.0
    scales = {(r.config.robots, r.config.time_scale) for r in sweepfile.expand(spec)}
    assert scales == {(1, 12.5), (2, 6.0)}
    assert spec.to_dict()["time_scale_by_robots"] == {"1": 12.5, "2": 6.0}


def test_coordination_and_start_are_grid_dimensions_sharing_their_seeds():
    spec = parse(GOOD.replace("runs = 2", 'runs = 1\ncoordination = ["paper", "ours"]\n'
                              'start = ["corner", "spread"]'))  # fmt: skip
    runs = sweepfile.expand(spec)
    assert len(runs) == 4 * 2 * 2
    ids = {r.run_id: r.config for r in runs}
    # Defaults leave the id as older sweeps wrote it; other values name themselves.
    assert ids["n01-c5-l2-k1"].coordination == "ours"
    assert ids["n01-c5-l2-paper-spread-k1"].start == "spread"
    assert ids["n01-c5-l2-spread-k1"].coordination == "ours"
    # The variants of a point run on the same random numbers.
    seeds = {c.seed for rid, c in ids.items() if rid.startswith("n01-c5-l2-")}
    assert len(seeds) == 1
    assert len({r.point for r in runs}) == len(runs)


@pytest.mark.parametrize(
    ("line", "words"),
    [
        ('coordination = ["paper", "nobody"]', "grid.coordination: expected one of paper, ours"),
        ("start = []", "grid.start: empty list"),
        ('start = ["spread", "spread"]', "grid.start: duplicate values"),
    ],
)
def test_bad_coordination_or_start_names_the_key(line, words):
    with pytest.raises(UsageError) as e:
        parse(GOOD.replace("runs = 2", "runs = 2\n" + line))
    assert words in str(e.value)


def test_aodv_profile_is_a_run_option_recorded_only_when_chosen():
    default = sweepfile.expand(parse(GOOD))
    assert all("aodv_profile" not in plan_dict(r.config) for r in default)  # older plans
    ns3 = sweepfile.expand(parse(GOOD.replace("capture = true", 'aodv_profile = "ns3"')))
    assert {r.config.aodv_profile for r in ns3} == {"ns3"}
    with pytest.raises(UsageError, match="run.aodv_profile: expected one of rfc, ns3"):
        parse(GOOD.replace("capture = true", 'aodv_profile = "olsr"'))


def test_routing_and_map_as_grid_dimensions_name_themselves_and_share_seeds(tmp_path):
    (tmp_path / "maps").mkdir()
    text = GOOD.replace("runs = 2", 'runs = 1\nrouting = ["aodv", "oracle"]\n'
                        'map = ["empty", "maps/office.png"]').replace(
        "capture = true", 'capture = true\nrange_model = "los"\nwall_loss_pct = 40')  # fmt: skip
    spec = sweepfile.parse(tomllib.loads(text), tmp_path / "p.toml")
    runs = sweepfile.expand(spec)
    assert len(runs) == 4 * 2 * 2
    ids = {r.run_id: r.config for r in runs}
    c = ids["n02-c20-l2-oracle-moffice-k1"]
    assert c.routing == "oracle" and c.map == str(tmp_path / "maps" / "office.png")
    assert c.range_model == "los" and c.wall_loss_pct == 40.0
    assert ids["n02-c20-l2-aodv-mempty-k1"].map is None
    assert len({c.seed for rid, c in ids.items() if rid.startswith("n02-c20-")}) == 1
    assert len({r.point for r in runs}) == len(runs)


@pytest.mark.parametrize(
    ("grid", "run", "words"),
    [
        ('routing = ["aodv", "olsr"]', "", "grid.routing: expected one of aodv, babel"),
        ('routing = ["aodv"]', 'routing = "babel"', "run.routing: already a grid dimension"),
        ("map = []", "", "grid.map: empty list"),
        ("", 'range_model = "fog"', "run.range_model: expected one of"),
        ("", "wall_loss_pct = 20", "run.wall_loss_pct: needs range_model los"),
        ('medium = ["veth", "hwsim"]', "", "grid.medium: expected one of veth, ns3-wifi"),
        ('medium = ["veth"]', 'medium = "veth"', "run.medium: already a grid dimension"),
        ("", 'wifi_standard = "80211b"', "run.wifi_standard: needs medium ns3-wifi"),
        ('medium = ["veth"]', 'wifi_rate = "DsssRate1Mbps"', "run.wifi_rate: needs medium"),
        ("", 'medium = "ns3-wifi"\nwifi_standard = "80211n"', "run.wifi_standard: expected"),
    ],
)
def test_bad_routing_map_or_radio_names_the_key(grid, run, words):
    text = GOOD.replace("runs = 2", "runs = 2\n" + grid).replace("capture = true", run)
    with pytest.raises(UsageError) as e:
        parse(text)
    assert words in str(e.value)


def test_medium_as_a_grid_dimension_names_itself_shares_seeds_and_keeps_veth_plain():
    text = GOOD.replace("runs = 2", 'runs = 1\nmedium = ["veth", "ns3-wifi"]').replace(
        "capture = true", 'wifi_standard = "80211b"\nwifi_rate = "DsssRate1Mbps"'
    )
    runs = sweepfile.expand(parse(text))
    assert len(runs) == 2 * 2 * 2
    ids = {r.run_id: r.config for r in runs}
    wifi, veth = ids["n02-c20-l2-ns3wifi-k1"], ids["n02-c20-l2-veth-k1"]
    assert (wifi.medium, wifi.wifi_standard, wifi.wifi_rate) == (
        "ns3-wifi", "80211b", "DsssRate1Mbps")  # fmt: skip
    # veth has no 802.11: its config keeps the defaults rather than claim one.
    assert (veth.medium, veth.wifi_standard, veth.wifi_rate) == ("veth", "80211a", "")
    assert wifi.seed == veth.seed
    assert len({r.point for r in runs}) == len(runs)
    assert plan_dict(wifi)["medium"] == "ns3-wifi"


def test_medium_fixed_in_run_is_not_in_the_ids():
    spec = parse(GOOD.replace("capture = true", 'medium = "ns3-wifi"\nwifi_loss = "logdistance"'))
    runs = sweepfile.expand(spec)
    assert {r.config.medium for r in runs} == {"ns3-wifi"}
    assert {r.config.wifi_loss for r in runs} == {"logdistance"}
    assert runs[0].run_id == "n01-c5-l2-k1"


def test_middleware_as_a_grid_dimension_names_itself_and_shares_seeds():
    text = GOOD.replace("runs = 2", 'runs = 1\nmiddleware = ["nanomsg", "zeromq-reqrep"]')
    runs = sweepfile.expand(parse(text))
    assert len(runs) == 2 * 2 * 2
    ids = {r.run_id: r.config for r in runs}
    plain, reqrep = ids["n02-c20-l2-nanomsg-k1"], ids["n02-c20-l2-zeromqreqrep-k1"]
    assert (plain.middleware, reqrep.middleware) == ("nanomsg", "zeromq-reqrep")
    assert plain.seed == reqrep.seed
    assert len({r.point for r in runs}) == len(runs)
    # A newer option: in a plan only when not the default, so older sweeps' plans stay.
    assert "middleware" not in plan_dict(plain)
    assert plan_dict(reqrep)["middleware"] == "zeromq-reqrep"


def test_middleware_fixed_in_run_is_not_in_the_ids_and_a_bad_one_is_named():
    runs = sweepfile.expand(parse(GOOD.replace("capture = true", 'middleware = "zeromq"')))
    assert {r.config.middleware for r in runs} == {"zeromq"}
    assert runs[0].run_id == "n01-c5-l2-k1"
    with pytest.raises(UsageError, match="run.middleware: expected one of nanomsg"):
        parse(GOOD.replace("capture = true", 'middleware = "mqtt"'))
