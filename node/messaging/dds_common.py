"""What both DDS topics (goals, maps) need of Cyclone DDS's Python binding, done safely.

Taking samples in a listener callback: Cyclone calls `on_data_available` from its own
threads with the reader looked up in its entity registry, which gives None while the reader
is still being made or already being deleted (data can arrive in both moments), and a take
on a reader being deleted raises. Both mean there is nothing to take; a callback that raised
would only print a traceback from a native thread. InvalidSamples (a writer went away, no
data) are skipped.

Whether a writer has a reader: the binding's `get_matched_subscriptions()` sizes a list by
one call and fills it by a second, and indexes past its end (IndexError) when a reader
matched in between, as readers do while a team discovers itself; the publication-matched
status is one call and one count.
"""

from collections.abc import Iterator

from cyclonedds.core import DDSException


def samples(reader, kind: type, batch: int) -> Iterator:
    """Every sample of `kind` `reader` holds now, taken `batch` at a time."""
    if reader is None:
        return
    while True:
        try:
            got = reader.take(N=batch)
        except DDSException:
            return
        if not got:
            return
        yield from (s for s in got if isinstance(s, kind))


def has_readers(writer) -> bool:
    """True when at least one reader is matched with `writer` now."""
    return writer.get_publication_matched_status().current_count > 0
