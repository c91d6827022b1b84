"""The pure parts of the ns3-wifi medium: its command line, MACs, protocol lines, the spec."""

import pytest

from topology.radio import ns3wifi
from topology.spec import Impairment, NetworkSpec


def spec(**kw) -> NetworkSpec:
    base = dict(name="u1", positions=((0, 0), (8, 0), (16.5, 0)), comm_range=10.0)
    return NetworkSpec(**(base | kw))


def test_robot_macs_are_unicast_locally_administered_and_distinct():
    macs = [ns3wifi.robot_mac(k) for k in range(1, 1001)]
    assert len(set(macs)) == 1000
    assert ns3wifi.robot_mac(1) == "02:00:0a:00:00:01"
    assert ns3wifi.robot_mac(300) == "02:00:0a:00:01:2c"
    for mac in macs:
        first = int(mac[:2], 16)
        assert first & 0x02 and not first & 0x01  # locally administered, unicast
    with pytest.raises(ValueError):
        ns3wifi.robot_mac(0)


def test_argv_names_every_robot_port_mac_and_position(monkeypatch):
    monkeypatch.setenv(ns3wifi.BINARY_ENV, "/x/tb-ns3-wifi")
    s = spec(medium="ns3-wifi", time_scale=4.0, wifi_rate="minstrel")
    argv = ns3wifi.argv(s, list(s.positions), "/run/s.sock")
    assert argv[0] == "/x/tb-ns3-wifi"
    opts = dict(zip(argv[1::2], argv[2::2], strict=True))
    assert opts["--socket"] == "/run/s.sock"
    assert float(opts["--range"]) == 10.0 and float(opts["--time-scale"]) == 4.0
    assert opts["--loss"] == "range" and opts["--standard"] == "80211a"
    assert opts["--rate"] == "minstrel"
    robots = [argv[i + 1] for i, a in enumerate(argv) if a == "--robot"]
    assert robots == [
        "rp1,02:00:0a:00:00:01,0.0,0.0",
        "rp2,02:00:0a:00:00:02,8.0,0.0",
        "rp3,02:00:0a:00:00:03,16.5,0.0",
    ]


def test_no_rate_option_means_the_standards_fastest():
    argv = ns3wifi.argv(spec(medium="ns3-wifi"), [(0, 0)] * 3, "/s")
    assert "--rate" not in argv


def test_positions_request_round_trips_floats_exactly():
    line = ns3wifi.positions_request([(0.1, 2.0), (-3.25, 1e-7)])
    assert line == "pos 0.1 2.0 -3.25 1e-07"
    assert [float(w) for w in line.split()[1:]] == [0.1, 2.0, -3.25, 1e-7]


def test_parse_links():
    assert ns3wifi.parse_links("links") == set()
    assert ns3wifi.parse_links("links 1-2 3-2") == {(1, 2), (2, 3)}
    with pytest.raises(ValueError):
        ns3wifi.parse_links("error unknown request")


def test_spec_defaults_to_veth_and_checks_the_medium():
    assert spec().medium == "veth"
    with pytest.raises(ValueError, match="unknown medium"):
        spec(medium="hwsim")
    with pytest.raises(ValueError, match="wifi loss"):
        spec(medium="ns3-wifi", wifi_loss="friis")
    with pytest.raises(ValueError, match="wifi standard"):
        spec(medium="ns3-wifi", wifi_standard="80211n")
    with pytest.raises(ValueError, match="WifiMode"):
        spec(medium="ns3-wifi", wifi_rate="Ofdm Rate; rm")
    with pytest.raises(ValueError, match="range model disc"):
        spec(medium="ns3-wifi", range_model="lossy")
    with pytest.raises(ValueError, match="no impairments"):
        spec(medium="ns3-wifi", impairment=Impairment(loss_pct=5))
    # The wifi options mean nothing to veth and are not checked there.
    assert spec(wifi_loss="whatever").medium == "veth"


def test_spec_round_trips_through_the_state_file():
    from topology import state

    s = spec(medium="ns3-wifi", wifi_loss="logdistance", wifi_rate="OfdmRate12Mbps")
    assert state.spec_from_dict(state.spec_to_dict(s)) == s


@pytest.mark.parametrize(
    "extra, words",
    [
        (["--medium", "hwsim"], ["invalid choice", "hwsim"]),
        (["--medium", "ns3-wifi", "--loss", "5"], ["no impairments"]),
        (["--medium", "ns3-wifi", "--range-model", "lossy"], ["range model disc"]),
        (["--medium", "ns3-wifi", "--wifi-standard", "80211n"], ["invalid choice"]),
    ],
)
def test_net_up_medium_arguments_are_one_line_exit_2(extra, words, capsys):
    from testbed import cli

    assert cli.main(["net", "up", "u1", "--robots", "2", "--comm-range", "5", *extra]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    for w in words:
        assert w in err[0]


def test_medium_for_picks_the_specs_medium():
    from topology.radio.veth import VethMedium

    veth = ns3wifi.medium_for(spec())
    wifi = ns3wifi.medium_for(spec(medium="ns3-wifi"))
    assert type(veth) is VethMedium
    assert isinstance(wifi, ns3wifi.Ns3Medium) and wifi.spec.medium == "ns3-wifi"


def test_a_medium_without_its_process_is_one_clear_error(tmp_path, monkeypatch):
    from common.errors import TestbedError

    monkeypatch.setenv("TESTBED_STATE_DIR", str(tmp_path))
    wifi = ns3wifi.Ns3Medium(spec(medium="ns3-wifi"))
    with pytest.raises(TestbedError, match="does not answer"):
        wifi.set_positions([(0, 0)] * 3)
