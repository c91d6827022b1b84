"""Whole lines out of a byte stream that arrives in chunks of any size.

A stream from outside (standard input, a socket client) may cut a line anywhere, send one
without end, or end without a final newline. `LineBuffer` keeps only the start of the line
not yet ended, never more than `limit` bytes of it, and looks at each byte once: its cost is
linear in what is read, whatever the chunking (joining the buffer to every chunk read, as a
`buf + chunk` loop does, is quadratic in the length of a line).
"""

from __future__ import annotations

TOO_LONG = None  # what `feed` and `end` give for a line longer than the limit


class LineBuffer:
    """Feed chunks in, get whole lines out (without their newline). A line longer than
    `limit` bytes is given once as TOO_LONG, as soon as it is seen to be, and the rest of it
    is dropped up to its newline; the lines after it come out as usual."""

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self._part = bytearray()  # the start of the line not yet ended
        self._skipping = False  # inside a line already given as TOO_LONG

    def feed(self, chunk: bytes) -> list[bytes | None]:
        out: list[bytes | None] = []
        start = 0
        while (nl := chunk.find(b"\n", start)) >= 0:
            if self._skipping:
                self._skipping = False  # the over-long line ends here
            elif len(self._part) + nl - start > self.limit:
                out.append(TOO_LONG)
            else:
                self._part += chunk[start:nl]
                out.append(bytes(self._part))
            self._part.clear()
            start = nl + 1
        if not self._skipping and start < len(chunk):
            if len(self._part) + len(chunk) - start > self.limit:
                out.append(TOO_LONG)
                self._part.clear()
                self._skipping = True
            else:
                self._part += chunk[start:]
        return out

    def end(self) -> list[bytes | None]:
        """At the end of the stream: its last line if that had no newline (exactly that
        line, once), else nothing."""
        last: list[bytes | None] = [] if self._skipping or not self._part else [bytes(self._part)]
        self._part.clear()
        self._skipping = False
        return last
