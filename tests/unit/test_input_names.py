"""Names and identifiers from outside are matched whole: a trailing newline, a Unicode digit or
a suffix never slips past a check that `testbed clean` and the kernel rely on."""

import pytest

from common.errors import UsageError
from testbed.cli import build_parser
from topology import names
from topology.spec import NetworkSpec


@pytest.mark.parametrize("bad", ["pqn\n", "pqn\r\n", "\npqn", "pqn\n\n", "pq n", "ab١"])
def test_a_testbed_name_with_a_newline_or_a_foreign_digit_is_refused(bad):
    with pytest.raises(ValueError, match="1-10 characters"):
        names.check_name(bad)
    with pytest.raises(UsageError, match="1-10 characters"):
        build_parser(["net", "up"]).parse_args(["net", "up", bad, "--robots", "2"])


def test_namespace_and_link_names_are_parsed_whole():
    assert names.parse_ns("tb-pqn-r3") == ("pqn", "r3")
    for bad in ("tb-pqn-r3\n", "tb-pqn-m\n", "tb-pqn-r٣", "tb-pqn\n-m"):
        assert names.parse_ns(bad) is None, bad
    assert names.parse_link_end("l2x3") == (2, 3)
    assert names.parse_link_end("l2x3\n") is None and names.parse_link_end("l2x٣") is None


def test_robot_references_are_ascii_digits_in_range():
    assert names.parse_robot_ref("r7") == 7 and names.parse_robot_ref("12") == 12
    for bad in ("r0", "0", "r²", "٣", "r1001", "1\n", "r", "", "r-1", "99999999999999999999"):
        with pytest.raises(ValueError, match="K or rK"):
            names.parse_robot_ref(bad)
    with pytest.raises(UsageError, match="K or rK"):
        build_parser(["net"]).parse_args(["net", "move", "abc", "r²", "1", "1"])


def test_a_wifi_rate_is_an_ascii_mode_name():
    spec = dict(name="w", positions=((0, 0), (1, 0)), comm_range=5.0, medium="ns3-wifi")
    assert NetworkSpec(**spec, wifi_rate="OfdmRate54Mbps").wifi_rate == "OfdmRate54Mbps"
    with pytest.raises(ValueError, match="WifiMode"):
        NetworkSpec(**spec, wifi_rate="OfdmRate５４Mbps")
