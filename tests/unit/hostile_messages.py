"""Issue 55's goal and re-plan messages from a hostile teammate (docs/robot-contract.md,
section 3), one table both robots' decoders are held to (tests.unit.test_hostile_messages)
and that live robots are sent (tests.integration.test_hostile_teammate).

Each row: an id, the message's bytes, and the contract's verdict for a team of `ROBOTS`
robots: ACCEPTED (a goal or re-plan request) or REFUSED (counted as malformed, dropped).
Before the fix the Python robot ended with status 3 on the rows marked "died" and decoded
the rows marked "two contracts" where the C++ robot refused them.
"""

from __future__ import annotations

import json

ROBOTS = 10
ACCEPTED, REFUSED = "accepted", "refused"

GOAL = {"k": "goal", "from": 3, "step": 120, "goal": [1.5, 2.0], "cost": 4.2, "n": 7}


def goal(**fields) -> bytes:
    """A goal message of robot 3 with `fields` replaced (json.dumps' text)."""
    return json.dumps({**GOAL, **fields}).encode()


def raw_text(key: str, literal: str) -> str:
    """GOAL's text with `key` given the JSON text `literal` as it stands (a literal
    json.dumps would not write, or would write otherwise)."""
    return json.dumps({**GOAL, key: "@@"}).replace('"@@"', literal)


def with_raw(key: str, literal: str) -> bytes:
    """raw_text in UTF-8."""
    return raw_text(key, literal).encode()


def surrogates(key: str, literal: str) -> bytes:
    """raw_text with its surrogates written as UTF-8 bytes would write them, were they
    allowed (Python's "surrogatepass"; CESU-8 for a pair)."""
    return raw_text(key, literal).encode("utf-8", "surrogatepass")


def nested(depth: int, inner: str = "") -> str:
    """`depth` arrays one inside another around `inner`."""
    return "[" * depth + inner + "]" * depth


TEXT = json.dumps(GOAL)
DIGITS_400 = "1" + "0" * 399

ROWS: list[tuple[str, bytes, str]] = [
    # died: OverflowError (int too large to convert to float) or RecursionError
    ("goal-x-400-digits", with_raw("goal", f"[{DIGITS_400}, 2.0]"), REFUSED),
    ("cost-400-digits", with_raw("cost", DIGITS_400), REFUSED),
    ("unknown-key-400-digits", with_raw("x", DIGITS_400), REFUSED),
    ("negative-400-digits", with_raw("x", "-" + DIGITS_400), REFUSED),
    ("int-5000-digits", with_raw("x", "7" * 5000), REFUSED),
    ("nested-100000", with_raw("x", nested(100_000)), REFUSED),
    ("nested-objects-100000", with_raw("x", '{"a":' * 100_000 + "1" + "}" * 100_000), REFUSED),
    ("nested-100000-unclosed", with_raw("x", "[" * 100_000), REFUSED),
    # the bound itself: 64 objects and arrays one inside another, the message's own counted
    ("nested-64", with_raw("x", nested(63)), ACCEPTED),
    ("nested-64-holding-a-number", with_raw("x", nested(63, "1")), ACCEPTED),
    ("nested-65", with_raw("x", nested(64)), REFUSED),
    ("nested-brackets-in-a-string", with_raw("x", json.dumps("[" * 1000)), ACCEPTED),
    # two contracts: decoded by the Python robot, refused by the C++ robot
    ("utf8-bom", b"\xef\xbb\xbf" + TEXT.encode(), REFUSED),
    ("utf16", TEXT.encode("utf-16"), REFUSED),
    ("utf16-le-no-bom", TEXT.encode("utf-16-le"), REFUSED),
    ("utf16-be-no-bom", TEXT.encode("utf-16-be"), REFUSED),
    ("utf32", TEXT.encode("utf-32"), REFUSED),
    ("utf32-le-no-bom", TEXT.encode("utf-32-le"), REFUSED),
    ("lone-surrogate-bytes", surrogates("x", '"\udc80"'), REFUSED),
    ("lone-surrogate-bytes-in-a-key",
     ('{"\ud800": 1, ' + TEXT[1:]).encode("utf-8", "surrogatepass"), REFUSED),
    ("surrogate-pair-bytes", surrogates("x", '"\ud83d\ude00"'), REFUSED),
    ("step-10^30", goal(step=10**30), REFUSED),
    ("n-2^63", goal(n=2**63), REFUSED),
    ("n-2^64", goal(n=2**64), REFUSED),
    ("step-minus-2^63-1", goal(step=-(2**63) - 1), REFUSED),
    # the bounds, on both sides
    ("n-2^63-1", goal(n=2**63 - 1), ACCEPTED),
    ("step-2^63-1", goal(step=2**63 - 1), ACCEPTED),
    ("unknown-key-minus-2^63", with_raw("x", str(-(2**63))), ACCEPTED),
    ("lone-surrogate-escaped", with_raw("x", '"\\udc80"'), ACCEPTED),
    ("fallback-lone-surrogate-escaped", with_raw("fallback", '"\\ud800"'), ACCEPTED),
    # floats: NaN and the infinities parse, and are refused where a finite number is asked for
    ("goal-nan", with_raw("goal", "[NaN, 1]"), REFUSED),
    ("goal-infinity", with_raw("goal", "[1, Infinity]"), REFUSED),
    ("cost-minus-infinity", with_raw("cost", "-Infinity"), REFUSED),
    ("goal-1e400", with_raw("goal", "[1e400, 1]"), REFUSED),
    ("cost-1e-400", with_raw("cost", "1e-400"), ACCEPTED),
    ("unknown-key-nan", with_raw("x", "NaN"), ACCEPTED),
    ("fallback-nan", with_raw("fallback", "NaN"), ACCEPTED),
    ("goal-float-of-400-digits", with_raw("goal", f"[0.{DIGITS_400}, 1]"), ACCEPTED),
    # empty, and not JSON at all
    ("empty", b"", REFUSED),
    ("whitespace", b" \n\t", REFUSED),
    ("nul", b"\x00", REFUSED),
    ("random-bytes", bytes(range(256)), REFUSED),
    ("two-values", TEXT.encode() * 2, REFUSED),
    ("truncated", TEXT.encode()[:-1], REFUSED),
]  # fmt: skip
