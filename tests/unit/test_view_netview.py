"""The drawn area of a `net up` network's view (testbed.view.netview.Extent)."""

from testbed.view.netview import Extent


def inside(extent: Extent, x: float, y: float, margin: float) -> bool:
    (x0, y0), (w, h) = extent.origin(), extent.size()
    return x0 <= x - margin and x + margin <= x0 + w and y0 <= y - margin and y + margin <= y0 + h


def test_every_robot_and_its_range_fit_even_at_negative_coordinates():
    e = Extent(10.0)
    chain = [(8.0 * i, 0.0) for i in range(5)]
    assert e.update(chain)
    assert all(inside(e, x, y, 10.0) for x, y in chain)  # r1 at (0, 0) is not cut in half
    assert e.update([*chain[:4], (30.0, -26.0)])  # a robot walks off: the square grows
    assert inside(e, 30.0, -26.0, 10.0) and inside(e, 0.0, 0.0, 10.0)


def test_the_square_only_grows_and_holds_the_map():
    e = Extent(5.0, box=(40.0, 30.0))
    assert not e.update([(20.0, 15.0)])  # inside the map: nothing changes
    assert inside(e, 0.0, 0.0, 0.0) and inside(e, 40.0, 30.0, 0.0)
    before = (e.origin(), e.size())
    assert not e.update([(6.0, 6.0)])  # its range ring inside the map too
    assert (e.origin(), e.size()) == before
    assert e.size()[0] == e.size()[1] >= 20.0
