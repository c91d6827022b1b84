"""A network's links while it is up: the link set the robots' positions call for, and what a
move changes in it (topology.network.Network applies the changes to the medium).

Theory of operation. `Links` holds the links up now (`current`: pair -> impairment), the
impairments set by hand per link (`by_hand`) and the robots taken out of everyone's radio
range (`isolated`: no link in the wanted set, whatever the positions say, until let back).
`wanted` is what the range model (topology.radio.ranges) makes of the positions, each link
with the testbed-wide impairment and its own combined. `changes` says what to add, remove and
re-impair: in full (a diff of every link against `current`) or, under the distance models
with the robots that moved known and none isolated, in O(links of the moved robots), with
`current` updated in place. A full diff leaves `current` to the caller, which takes it up
(`current = wanted`) once the medium has the links. Pure: positions in, link sets out.
"""

from common.errors import UsageError
from topology.radio import ranges
from topology.radio.los import MapError, Walls
from topology.spec import LOS_MODELS, NO_IMPAIRMENT, Impairment, NetworkSpec, Position

Pair = tuple[int, int]
# The range models whose links depend only on the distance of two robots: a move changes the
# moved robots' links and nothing else.
DISTANCE_MODELS = ("disc", "lossy")


class Links:
    """The links the positions call for and what changes them (see the module docstring)."""

    def __init__(self, spec: NetworkSpec, walls: Walls | None):
        self.spec = spec
        self.walls = walls  # the los range models' walls, from spec.map_png
        self.current: dict[Pair, Impairment] = {}
        self.by_hand: dict[Pair, Impairment] = {}  # set by hand, per link
        self.isolated: frozenset[int] = frozenset()  # robots out of everyone's range
        self._range_cache: dict[Pair, Impairment] | None = None  # the last range-model links
        self._adj: dict[int, set[Pair]] | None = None  # robot -> its links in current

    @staticmethod
    def walls_of(spec: NetworkSpec) -> Walls | None:
        """The walls of the spec's map for the line-of-sight range models, else None."""
        if not (spec.map_png and spec.range_model in LOS_MODELS):
            return None
        try:
            return Walls.from_png(spec.map_png, spec.map_cell)
        except MapError as exc:
            raise UsageError(str(exc)) from None

    def _range_links(
        self, positions: list[Position], moved: set[int] | None = None
    ) -> dict[Pair, Impairment]:
        """The range model's links for the current positions. With the distance models and
        `moved` given, only the links of the robots that moved are computed again (the rest
        come from the last call): what keeps a feed of many moves cheap at 1000 robots."""
        cached = self._range_cache
        if moved is not None and cached is not None and self.spec.range_model in DISTANCE_MODELS:
            links = {p: v for p, v in cached.items() if p[0] not in moved and p[1] not in moved}
            links.update(ranges.links_of(positions, moved, self.spec.comm_range,
                                         self.spec.range_model))  # fmt: skip
        else:
            links = ranges.wanted_links(
                positions, self.spec.comm_range, self.spec.range_model,
                self.walls, self.spec.wall_loss_pct,
            )  # fmt: skip
        self._range_cache = links
        return links

    def wanted(
        self, positions: list[Position], moved: set[int] | None = None
    ) -> dict[Pair, Impairment]:
        """The links (with their impairments) the positions call for; `moved`: the robots
        that moved since the last call, if known."""
        links = self._range_links(positions, moved)
        if self.isolated:
            links = {p: v for p, v in links.items() if not self.isolated.intersection(p)}
        base = self.spec.impairment
        if base.is_none and not self.by_hand:
            return links  # the common case, once per world step: nothing to combine
        return {
            p: base.combined(imp).combined(self.by_hand.get(p, NO_IMPAIRMENT))
            for p, imp in links.items()
        }

    def incremental(self, moved: set[int] | None) -> bool:
        """Whether a move of `moved` is diffed in place (`changes` updates `current`)."""
        return moved is not None and self.spec.range_model in DISTANCE_MODELS and not self.isolated

    def changes(
        self, positions: list[Position], moved: set[int] | None = None
    ) -> tuple[list[Pair], list[Pair], list[Pair], dict[Pair, Impairment]]:
        """What the positions change: (add, remove, change, the links wanted or, diffed in
        place, the moved robots' new links)."""
        if self.incremental(moved):
            assert moved is not None  # incremental() says so
            return self._diff_moved(positions, moved)
        wanted = self.wanted(positions)
        add, remove, change = ranges.diff(self.current, wanted)
        self._adj = None
        return add, remove, change, wanted

    def _diff_moved(
        self, positions: list[Position], moved: set[int]
    ) -> tuple[list[Pair], list[Pair], list[Pair], dict[Pair, Impairment]]:
        """What a move of `moved` changes, in O(links of the moved robots), with self.current
        updated in place: only links of a robot that moved can change under the distance
        models. A feed of single moves at 1000 robots would otherwise pay for every link
        (diffing 2000 links: ~4 ms) per update. Returns (add, remove, change, new links)."""
        if self._adj is None:
            self._adj = {}
            for p in self.current:
                self._adj.setdefault(p[0], set()).add(p)
                self._adj.setdefault(p[1], set()).add(p)
        self._range_cache = None  # wanted() recomputes in full from now on
        new = ranges.links_of(positions, moved, self.spec.comm_range, self.spec.range_model)
        base = self.spec.impairment
        if not base.is_none or self.by_hand:
            new = {
                p: base.combined(imp).combined(self.by_hand.get(p, NO_IMPAIRMENT))
                for p, imp in new.items()
            }
        old = set().union(*(self._adj.get(k, ()) for k in moved))
        add = sorted(set(new) - old)
        remove = sorted(old - set(new))
        change = sorted(p for p in old & set(new) if new[p] != self.current[p])
        for p in remove:
            del self.current[p]
            self._adj[p[0]].discard(p)
            self._adj[p[1]].discard(p)
        for p in add:
            self._adj.setdefault(p[0], set()).add(p)
            self._adj.setdefault(p[1], set()).add(p)
        for p in add + change:
            self.current[p] = new[p]
        return add, remove, change, new

    def retake(self, positions: list[Position], by_hand: dict[Pair, Impairment]) -> None:
        """Take up links another process applied (from the state file): the impairments set by
        hand, and the links the positions make with them, as they are now."""
        self.by_hand = by_hand
        self._range_cache = None
        self.current = self.wanted(positions)
        self._adj = None
