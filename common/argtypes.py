"""The one number check of every command line in the project (testbed, node, aodv).

`number(kind, what, ...)` is an argparse `type=`: it turns the text into an int or a float
and rejects, in one line that names the value and what it is for, anything that is not a
number, not finite, or out of range. argparse then prints that line and exits with status 2.
`checked(check)` makes an argparse type of any check that raises ValueError with such a line.
"""

from __future__ import annotations

import argparse
import functools
import math
from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")
Number = TypeVar("Number", int, float)


def number(
    kind: type[Number],
    what: str,
    *,
    minimum: float | None = None,
    above: float | None = None,
    magnitude: float | None = None,
) -> Callable[[str], Number]:
    """An argparse type for a finite `kind` (int or float) that is at least `minimum`,
    greater than `above` and at most `magnitude` in absolute value (each when given): e.g.
    `number(float, "comm range", above=0)`."""

    def parse(text: str) -> Number:
        try:
            value = kind(text)
        except ValueError:
            noun = "a whole number" if kind is int else "a number"
            raise argparse.ArgumentTypeError(f"{what} must be {noun}, not {text!r}") from None
        if isinstance(value, float) and not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{what} must be finite, not {text!r}")
        if above is not None and not value > above:
            raise argparse.ArgumentTypeError(f"{what} must be greater than {above:g}, not {text}")
        if minimum is not None and value < minimum:
            least = "not be negative" if minimum == 0 else f"be at least {minimum:g}"
            raise argparse.ArgumentTypeError(f"{what} must {least}, not {text}")
        if magnitude is not None and abs(value) > magnitude:
            raise argparse.ArgumentTypeError(
                f"{what} must be within {magnitude:,.0f} of 0, not {text}"
            )
        return value

    return parse


def checked(check: Callable[[str], T]) -> Callable[[str], T]:
    """An argparse `type=` from `check`, which raises ValueError with a one-line reason: that
    reason is the line argparse prints (for a ValueError it would say only "invalid value")."""

    @functools.wraps(check)
    def parse(text: str) -> T:
        try:
            return check(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    return parse
