"""What both DDS topics (goals, maps) need of Cyclone DDS's Python binding, done safely.

Taking samples in a listener callback: Cyclone calls `on_data_available` from its own
threads with the reader looked up in its entity registry, which gives None while the reader
is still being made or already being deleted (data can arrive in both moments), and a take
on a reader being deleted raises. Both mean there is nothing to take; a callback that raised
would only print a traceback from a native thread. InvalidSamples (a writer went away, no
data) are skipped. The binding turns a sample's bytes into the IDL type in `take`, on our
side: bytes that are not one (a writer of another make, a hostile one) raise there
(struct.error); the batch that held them is lost, `undecodable` is called once for it, and
the taking goes on.

Whether a writer has a reader: the binding's `get_matched_subscriptions()` sizes a list by
one call and fills it by a second, and indexes past its end (IndexError) when a reader
matched in between, as readers do while a team discovers itself; the publication-matched
status is one call and one count.
"""

import logging
from collections.abc import Callable, Iterator

from cyclonedds.core import DDSException

log = logging.getLogger(__name__)


def _nothing() -> None:
    pass


def samples(reader, kind: type, batch: int, undecodable: Callable[[], None] = _nothing) -> Iterator:
    """Every sample of `kind` `reader` holds now, taken `batch` at a time; `undecodable()`
    for each take that met bytes that are not a `kind` (at most `batch` in a row)."""
    if reader is None:
        return
    failed = 0
    while failed < batch:
        try:
            got = reader.take(N=batch)
        except DDSException:
            return
        except Exception as e:  # the binding's deserializing of a peer's bytes
            log.debug("dropped samples that do not decode: %r", e)
            failed += 1
            undecodable()
            continue
        if not got:
            return
        failed = 0
        yield from (s for s in got if isinstance(s, kind))


def has_readers(writer) -> bool:
    """True when at least one reader is matched with `writer` now."""
    return writer.get_publication_matched_status().current_count > 0
