"""Taking samples in a Cyclone DDS listener callback, for both DDS topics (goals, maps).

Cyclone calls `on_data_available` from its own threads with the reader looked up in its
entity registry, which gives None while the reader is still being made or already being
deleted (data can arrive in both moments), and a take on a reader being deleted raises.
Both mean there is nothing to take; a callback that raised would only print a traceback from
a native thread. InvalidSamples (a writer went away, no data) are skipped.
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
