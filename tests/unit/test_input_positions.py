"""Coordinates that are not finite or absurdly far are refused at every entry: `--positions`,
`net move`, a NetworkSpec (what traces and layouts make), before any network exists."""

import pytest

from common.errors import UsageError
from testbed.cli import build_parser
from topology.spec import MAX_COORD_M, NetworkSpec


@pytest.mark.parametrize("positions", ["nan,nan 0,0", "0,0 inf,1", "1e308,0 0,0", "0,-2e7 1,1"])
def test_net_up_positions_must_be_finite_and_within_the_limit(positions):
    argv = ["net", "up", "pos", "--robots", "2", "--positions", positions]
    with pytest.raises(UsageError, match="finite|beyond"):
        build_parser(argv).parse_args(argv)


@pytest.mark.parametrize("xy", [("nan", "0"), ("1e300", "0"), ("0", "-1e8")])
def test_net_move_coordinates_must_be_finite_and_within_the_limit(xy):
    argv = ["net", "move", "pos", "r1", *xy]
    with pytest.raises(UsageError):
        build_parser(argv).parse_args(argv)


@pytest.mark.parametrize(
    "position", [(float("nan"), 0.0), (0.0, float("-inf")), (1e308, 0.0), (0.0, -1.5e7)]
)
def test_a_spec_refuses_a_position_that_is_not_finite_or_absurd(position):
    with pytest.raises(ValueError, match="position of r2"):
        NetworkSpec(name="pos", positions=((0.0, 0.0), position), comm_range=5.0)


def test_positions_at_the_limit_are_accepted():
    spec = NetworkSpec(name="pos", positions=((-MAX_COORD_M, MAX_COORD_M),), comm_range=5.0)
    assert spec.positions == ((-MAX_COORD_M, MAX_COORD_M),)
    argv = ["net", "up", "pos", "--robots", "1", "--comm-range", "5", "--positions=-1e7,1e7"]
    assert build_parser(argv).parse_args(argv).positions == [(-1e7, 1e7)]
