"""The disc model's slack (topology.radio.slack) and Network.set_positions' use of it: moves
within the slack never leave a link set that the range model would not give, and the links
that set_positions keeps are always the ones deciding in full would give."""

import math

from hypothesis import given, settings
from hypothesis import strategies as st

from topology.network import Network
from topology.radio import ranges
from topology.radio.slack import Slack
from topology.spec import NetworkSpec

coord = st.floats(0.0, 60.0)
team = st.lists(st.tuples(coord, coord), min_size=1, max_size=8)
# Each step moves some robots a little (as a world step does), some not at all.
move = st.tuples(st.floats(-0.15, 0.15), st.floats(-0.15, 0.15))
steps = st.lists(st.lists(move, min_size=8, max_size=8), min_size=1, max_size=60)


def walk(start, moves):
    pos = list(start)
    for step in moves:
        pos = [(x + dx, y + dy) for (x, y), (dx, dy) in zip(pos, step, strict=False)]
        yield pos


@settings(max_examples=300, deadline=None)
@given(team, steps, st.sampled_from([0.5, 5.0, 20.0]))
def test_while_the_slack_holds_the_links_are_the_last_decided(start, moves, comm_range):
    slack = Slack(NetworkSpec(name="tslack", positions=tuple(start), comm_range=comm_range))
    decided = ranges.wanted_links(start, comm_range)
    slack.measure(start)
    held = 0
    for pos in walk(start, moves):
        if slack.holds(pos):
            held += 1
            assert ranges.wanted_links(pos, comm_range) == decided
        else:
            decided = ranges.wanted_links(pos, comm_range)
            slack.measure(pos)


def test_the_slack_is_the_nearest_pair_to_the_range_and_moves_spend_it():
    slack = Slack(NetworkSpec(name="tslack", positions=((0.0, 0.0),), comm_range=10.0))
    slack.measure([(0.0, 0.0), (7.0, 0.0), (30.0, 0.0)])  # gaps 3, 13, 20: the least is 3
    assert slack.holds([(0.0, 0.0), (7.0, 1.0), (30.0, 0.5)])  # spends 1 + 0.5
    assert slack.holds([(0.0, 0.0), (7.0, 2.0), (30.0, 0.5)])  # spends 1: 0.5 left
    assert not slack.holds([(0.0, 0.0), (7.0, 2.6), (30.0, 0.5)])  # 0.6 > 0.5
    assert not slack.holds([(0.0, 0.0), (7.0, 2.6), (30.0, 0.5)])  # spent: decide in full
    slack.measure([(0.0, 0.0), (10.0, 0.0)])  # a pair right at the range: no slack
    assert not slack.holds([(0.0, 0.0), (10.0, 0.0)])
    slack.measure([(1.0, 1.0)])  # one robot: no pair, never a link
    assert slack.holds([(5.0, 5.0)])
    slack.measure([(1.0, 1.0)])
    assert not slack.holds([(1.0, 1.0)], off=True)  # isolated robots: decide in full
    assert not slack.holds([(1.0, 1.0)])  # and again after, until measured
    lossy = NetworkSpec(name="tslack", positions=((0.0, 0.0),), comm_range=10.0,
                        range_model="lossy")  # fmt: skip
    other = Slack(lossy)
    other.measure([(1.0, 1.0)])
    assert not other.holds([(1.0, 1.0)])  # its impairments change with any move


class Recorder:
    """The medium's side of set_positions, recorded instead of done in the kernel."""

    def __init__(self):
        self.up: set = set()
        self.calls = 0

    def create_pairs(self, pairs):
        pass

    def set_link_impairment(self, i, j, imp):
        pass

    def set_links(self, add, remove):
        self.calls += 1
        self.up |= set(add)
        self.up -= set(remove)


@settings(max_examples=100, deadline=None)
@given(team, steps, st.sampled_from([0.5, 5.0, 20.0]), st.data())
def test_set_positions_keeps_the_links_deciding_in_full_gives(start, moves, comm_range, data):
    """World steps, with now and then a robot moved by hand in between (Network.move: it
    decides its own links), and robots isolated for a while (the links follow that too)."""
    net = Network(NetworkSpec(name="tslack", positions=tuple(start), comm_range=comm_range))
    medium = net.medium = Recorder()  # type: ignore[assignment]
    net.set_positions(start)
    n = len(start)
    for pos in walk(start, moves):
        if data.draw(st.integers(0, 5)) == 0:
            k = data.draw(st.integers(1, n))
            net.move(k, (pos[k - 1][0] + data.draw(st.floats(-3, 3)), pos[k - 1][1]))
            pos[k - 1] = net.positions[k - 1]
        if data.draw(st.integers(0, 9)) == 0:
            net.set_isolated(data.draw(st.sets(st.integers(1, n), max_size=1)))
        added, removed = net.set_positions(pos)
        wanted = set(ranges.wanted_links(pos, comm_range))
        wanted = {p for p in wanted if not net.isolated.intersection(p)}
        assert medium.up == set(net.current) == wanted
        assert not (set(added) & set(removed))


def test_set_positions_skips_the_range_model_while_nothing_can_change():
    start = [(0.0, 0.0), (5.0, 0.0), (40.0, 0.0)]
    net = Network(NetworkSpec(name="tslack", positions=tuple(start), comm_range=20.0))
    medium = net.medium = Recorder()  # type: ignore[assignment]
    net.set_positions(start)
    for k in range(1, 50):  # robot 2 walks 4.9 m toward 3: the 1-2 gap was 15, 2-3's 15
        net.set_positions([(0.0, 0.0), (5.0 + 0.1 * k, 0.0), (40.0, 0.0)])
    assert medium.calls == 1  # the first decision only
    assert set(net.current) == {(1, 2)}
    net.set_positions([(0.0, 0.0), (20.5, 0.0), (40.0, 0.0)])  # 1-2 breaks, 2-3 joins
    assert set(net.current) == {(2, 3)} and medium.calls == 2
    assert math.isclose(net.positions[1][0], 20.5)
