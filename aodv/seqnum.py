"""Destination sequence numbers with wraparound (RFC 3561 section 6.1).

RFC 3561 6.1: "Comparison ... MUST be done using signed 32-bit arithmetic, this is
necessary to accomplish sequence number rollover."
"""

MASK = 0xFFFFFFFF


def diff(a: int, b: int) -> int:
    """a - b as a signed 32-bit number: > 0 when a is newer than b."""
    d = (a - b) & MASK
    return d - 0x1_0000_0000 if d & 0x8000_0000 else d


def newer(a: int, b: int) -> bool:
    """True if sequence number a is strictly fresher than b, rollover included."""
    return diff(a, b) > 0


def at_least(a: int, b: int) -> bool:
    """True if a is as fresh as b or fresher."""
    return diff(a, b) >= 0


def increment(a: int) -> int:
    """The next sequence number (RFC 3561 6.1: increments wrap modulo 2**32)."""
    return (a + 1) & MASK


def newest(a: int, b: int) -> int:
    """The fresher of two sequence numbers."""
    return a if at_least(a, b) else b
