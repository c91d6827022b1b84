"""The data path of the AODV core: what data does to routes (RFC 3561 6.2), and the copy of
the valid routes that the kernel holds.

Theory of operation
-------------------
Data never passes through the protocol core (aodv.core): the kernel forwards it along the
routes the core installs. `DataPath` is the core's side of that. It keeps `installed`, what
the kernel was told (destination -> next hop, hops), and after every event `sync` returns
the InstallRoute and DeleteRoute actions that bring the kernel in line with the valid
entries of the routing table. The daemon reports data that crossed a route (`used`, 6.2:
the route, and the route to its next hop, live ACTIVE_ROUTE_TIMEOUT longer) and a packet
the kernel found no route for while the table holds a valid one (`reinstall`: the kernel
lost it behind our back). Data without any route goes to route discovery (our own) or
route maintenance (others', 6.11 ii); buffering is route discovery's (6.3).

State is the shared aodv.state.NodeState; no clock, no IO: methods take `now`.
"""

from __future__ import annotations

from aodv.actions import Action, DeleteRoute, InstallRoute
from aodv.state import NodeState


class DataPath:
    def __init__(self, state: NodeState) -> None:
        self.s = state
        self.installed: dict[str, tuple[str, int]] = {}

    def used(self, now: float, addr: str) -> None:
        """Data to or from `addr` crossed this node recently.

        RFC 6.2: "Each time a route is used to forward a data packet, its Active Route
        Lifetime field of the source, destination and the next hop on the path to the
        destination is updated to be no less than the current time plus
        ACTIVE_ROUTE_TIMEOUT." The daemon reports sources and destinations alike.
        """
        s = self.s
        r = s.table.valid(addr)
        if r is not None:
            s.refresh(r, now + s.p.active_route_timeout)
            nh = s.table.valid(r.next_hop)
            if nh is not None:
                s.refresh(nh, now + s.p.active_route_timeout)

    def reinstall(self, dst: str) -> None:
        """The kernel has lost the valid route to `dst`: the next `sync` installs it."""
        self.installed.pop(dst, None)

    def sync(self) -> list[Action]:
        """Install/delete actions that bring the kernel in line with the valid entries.
        This runs after every event, so it looks only at the entries the event touched
        (RoutingTable.take_touched), or at all of them after a loop over the table."""
        table = self.s.table
        touched = table.take_touched()
        if touched is None:
            return self._sync_all()
        acts: list[Action] = []
        installed = self.installed
        gone = []
        for dest in touched:
            r = table.peek(dest)
            if r is None:
                if dest in installed:
                    gone.append(dest)
            elif r.valid:
                key = r.kernel_key()
                if installed.get(dest) != key:
                    installed[dest] = key
                    acts.append(InstallRoute(dest, *key))
            elif dest in installed:
                del installed[dest]
                acts.append(DeleteRoute(dest))
        if len(gone) > 1:  # in the order the full pass deletes them
            left = set(gone)
            gone = [d for d in installed if d in left]
        for dest in gone:
            del installed[dest]
            acts.append(DeleteRoute(dest))
        return acts

    def _sync_all(self) -> list[Action]:
        """sync over every entry (one pass over the table)."""
        acts: list[Action] = []
        table = self.s.table
        installed = self.installed
        n_valid = 0
        for r in table.peek_all():
            if r.valid:
                n_valid += 1
                key = r.kernel_key()
                if installed.get(r.dest) != key:
                    installed[r.dest] = key
                    acts.append(InstallRoute(r.dest, *key))
            elif r.dest in installed:
                del installed[r.dest]
                acts.append(DeleteRoute(r.dest))
        if len(installed) > n_valid:  # installed entries that left the table
            for dest in [d for d in installed if not self._valid_in(table, d)]:
                del installed[dest]
                acts.append(DeleteRoute(dest))
        return acts

    @staticmethod
    def _valid_in(table, dest: str) -> bool:
        r = table.peek(dest)
        return r is not None and r.valid
