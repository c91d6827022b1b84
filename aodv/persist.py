"""What a restarted daemon must not forget: its own sequence number and RREQ ID (RFC 6.13).

RFC 3561 6.13: "A node can lose its sequence number or the record of the last RREQ ID it
used after a reboot" and neighbours may still hold both; a node that came back with lower
ones would send RREQs its neighbours drop as duplicates, and replies older than the routes
they replace. Decision: the daemon persists a *high-water mark* for each, `block` ahead of
the value in use, in a small JSON file that lives as long as the network (the testbed's run
directory). A value is never sent before a mark above it is on disk (`cover` runs before
the messages leave), so a restart that resumes at the marks is above everything used, at a
cost of one file write per `block` messages. The file's presence is also how a restart is
told from a first start: the RFC's DELETE_PERIOD wait applies whenever it exists.
"""

from __future__ import annotations

import logging

from aodv import seqnum
from common.jsonfile import read_json, write_json_atomic

log = logging.getLogger(__name__)


class CounterStore:
    block = 1024

    def __init__(self, path: str) -> None:
        self.path = path
        self.writes = 0
        self._seq_mark: int | None = None
        self._id_mark: int | None = None

    def load(self) -> tuple[int, int] | None:
        """(sequence number, RREQ ID) to resume from, or None on a first start.

        A file that exists but cannot be read still means a restart: the numbers are then
        unknown, and the DELETE_PERIOD wait is all that protects the neighbours (the RFC's
        own remedy), so the counters start again from 0."""
        data = read_json(self.path)
        try:
            seq, rid = int(data["seq"]) & seqnum.MASK, int(data["rreq_id"]) & seqnum.MASK
        except (TypeError, KeyError, ValueError):
            try:
                with open(self.path, "rb"):
                    pass
            except FileNotFoundError:
                return None
            except OSError:
                pass
            log.warning("counter file %s unreadable: numbers start again from 0", self.path)
            return 0, 0
        self._seq_mark, self._id_mark = seq, rid
        return seq, rid

    def cover(self, seq: int, rreq_id: int) -> None:
        """Make sure the marks on disk are above `seq` and `rreq_id` (call before sending)."""
        if (
            self._seq_mark is not None
            and self._id_mark is not None
            and seqnum.newer(self._seq_mark, seq)
            and seqnum.newer(self._id_mark, rreq_id)
        ):
            return
        self._seq_mark = (seq + self.block) & seqnum.MASK
        self._id_mark = (rreq_id + self.block) & seqnum.MASK
        write_json_atomic(self.path, {"seq": self._seq_mark, "rreq_id": self._id_mark})
        self.writes += 1
