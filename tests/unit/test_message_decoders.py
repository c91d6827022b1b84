"""The two robots' message decoders are one (docs/robot-contract.md, section 3; issue 55):
Hypothesis writes hostile goal and re-plan messages and each goes to node.wire.parse_msg and
to the C++ robot's (`tb-robot --decode msg`, native/robot/selftest.cc). Both must give the
same verdict, accept or refuse, and the same decoded value when they accept (floats to the
bit, the sign of zero included; `true` is the integer 1, not a boolean, where an integer is
asked for); Python may raise nothing but ValueError, and tb-robot nothing but its two
statuses.

The messages: valid ones with fields of any JSON (integers of any length, around the 64-bit
bounds, NaN and the infinities, strings with escapes and lone surrogates, nesting around the
bound of 64), then as bytes in UTF-8, behind a byte-order mark, in UTF-16 or UTF-32, with
surrogates encoded, cut, flipped or grown; and arbitrary bytes.

Skipped where build/tb-robot was not built (`make setup`; no g++ or libnng-dev).
"""

import json
import math
import subprocess

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from node import wire
from node.native import TB_ROBOT, unbuilt_reason

NOT_BUILT = None if TB_ROBOT.is_file() else (unbuilt_reason() or "build/tb-robot is missing")
pytestmark = pytest.mark.skipif(NOT_BUILT is not None, reason=f"no C++ robot: {NOT_BUILT}")

ROBOTS = 10
SETTINGS = settings(max_examples=150, deadline=None, database=None,
                    suppress_health_check=[HealthCheck.too_slow])  # fmt: skip


def cpp_decode(data: bytes) -> dict | None:
    """The C++ robot's decoding, in its self-test's form; None when it refused."""
    p = subprocess.run([str(TB_ROBOT), "--decode", "msg", "--robots", str(ROBOTS)],
                       input=data, capture_output=True, timeout=20)  # fmt: skip
    assert p.returncode in (0, 1) and not p.stderr, (p.returncode, p.stderr[-300:])
    out = p.stdout.decode()
    if p.returncode == 1:
        assert out.startswith("refused: ") and out.count("\n") == 1, out
        return None
    return json.loads(out)


def py_decode(data: bytes) -> dict | None:
    """node.wire.parse_msg's decoding in the self-test's form; None when it refused."""
    try:
        m = wire.parse_msg(data, ROBOTS)
    except ValueError:
        return None
    out = {"k": m["k"], "from": m["from"], "step": m["step"], "goal": list(m["goal"])}
    if m["k"] == "goal":
        out.update(cost=m["cost"], fallback=m["fallback"])
    out["n"] = m["n"]
    return out


def identical(a, b) -> bool:
    """Equal, floats to the bit (the sign of zero too), bool apart from int."""
    if type(a) is not type(b):
        return False
    if isinstance(a, float):
        return a == b and math.copysign(1, a) == math.copysign(1, b)
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(identical(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return len(a) == len(b) and all(identical(x, y) for x, y in zip(a, b, strict=True))
    return a == b


# ------------------------------------------------------------------ JSON texts, hostile

INT64 = 2**63
int_literals = st.one_of(
    st.integers(-3, 12),
    st.integers(-(2**70), 2**70),
    st.sampled_from([INT64 - 1, INT64, -INT64, -INT64 - 1, 2**64, 10**30]),
    st.integers(20, 600).map(lambda n: "9" * n),
).map(str)
float_literals = st.one_of(
    st.floats().map(json.dumps),  # NaN, Infinity, -Infinity as Python writes them
    st.sampled_from(["-0.0", "-0", "0e0", "1e400", "-1e400", "1e-400", "4.9e-324", "1E+2",
                     "0." + "3" * 400, "2." + "0" * 30 + "1", "1.7976931348623157e308"]),
)  # fmt: skip
string_literals = st.one_of(
    st.text(max_size=6).map(json.dumps),  # lone surrogates escaped (ensure_ascii)
    st.text(max_size=6).map(lambda s: json.dumps(s, ensure_ascii=False)),
    st.sampled_from(['"\\ud800"', '"\\udc00x"', '"\\ud83d\\ude00"', '"\\ud800\\u0041"',
                     '"goal"', '"replan"', '""', '"[[[["', '"\\u0000"']),
)  # fmt: skip
scalars = st.one_of(int_literals, float_literals, string_literals,
                    st.sampled_from(["true", "false", "null"]))  # fmt: skip


def nested_value(depth: int, inner: str, kind: str) -> str:
    """`depth` arrays or objects one inside another around `inner` (nothing: the innermost
    is empty)."""
    if kind == "[":
        return "[" * depth + inner + "]" * depth
    if not inner:
        return '{"a": ' * (depth - 1) + "{}" + "}" * (depth - 1)
    return '{"a": ' * depth + inner + "}" * depth


deep = st.builds(nested_value, st.integers(55, 70), st.sampled_from(["", "1", "[]"]),
                 st.sampled_from(["[", "{"]))  # fmt: skip
values = st.recursive(
    scalars,
    lambda inner: st.one_of(
        st.lists(inner, max_size=3).map(lambda v: "[" + ", ".join(v) + "]"),
        st.lists(st.tuples(string_literals, inner), max_size=3).map(
            lambda kv: "{" + ", ".join(f"{k}: {v}" for k, v in kv) + "}"
        ),
    ),
    max_leaves=6,
)
numbers = st.one_of(int_literals, float_literals)
points = st.one_of(
    st.tuples(numbers, numbers).map(lambda p: f"[{p[0]}, {p[1]}]"), values, deep
)  # fmt: skip


finite = st.one_of(
    st.floats(allow_nan=False, allow_infinity=False).map(json.dumps),
    st.integers(-INT64, INT64 - 1).map(str),
    st.sampled_from(["-0.0", "-0", "1e-400", "4.9e-324", "0." + "3" * 400, "1E+2", "true"]),
)  # fmt: skip
non_negative = st.one_of(
    st.floats(0, allow_infinity=False).map(json.dumps),
    st.integers(0, INT64 - 1).map(str),
    st.sampled_from(["-0.0", "0", "1e-400", "false", "2." + "0" * 30 + "1"]),
)  # fmt: skip
# Each field: a value the contract takes, mostly; a hostile one (HOSTILE) at times.
PLAUSIBLE = {
    "k": st.sampled_from(['"goal"', '"replan"']),
    "from": st.one_of(st.integers(0, 11).map(str), st.sampled_from(["true", "false"])),
    "step": st.one_of(st.integers(0, INT64 - 1).map(str), st.sampled_from(["0", "true"])),
    "goal": st.tuples(finite, finite).map(lambda p: f"[{p[0]}, {p[1]}]"),
    "cost": non_negative,
    "fallback": values,
    "n": st.one_of(st.integers(1, INT64 - 1).map(str), st.just("null")),
    "x": values,
}
HOSTILE = {
    "k": values,
    "from": st.one_of(int_literals, values),
    "step": st.one_of(int_literals, values),
    "goal": points,
    "cost": st.one_of(numbers, values),
    "fallback": values,
    "n": st.one_of(int_literals, values),
    "x": st.one_of(deep, int_literals, float_literals),
}
REQUIRED = ("k", "from", "step", "goal")


@st.composite
def message_texts(draw) -> str:
    """A goal or re-plan message's text: each field plausible or, one time in six,
    hostile; a required field left out one time in ten, an optional one half the time."""
    parts = []
    for key, plausible in PLAUSIBLE.items():
        wanted = draw(st.integers(0, 9)) != 0 if key in REQUIRED else draw(st.booleans())
        if wanted:
            value = draw(HOSTILE[key] if draw(st.integers(0, 5)) == 0 else plausible)
            parts.append(f'"{key}": {value}')
    draw(st.randoms()).shuffle(parts)
    return "{" + ", ".join(parts) + "}"


def as_bytes(text: str, how: str) -> bytes:
    """The text as a peer might send it."""
    if how == "bom":
        return b"\xef\xbb\xbf" + text.encode("utf-8", "surrogatepass")
    if how == "surrogatepass":
        return text.encode("utf-8", "surrogatepass")
    if how in ("utf-16", "utf-16-le", "utf-16-be", "utf-32", "utf-32-le"):
        return text.encode(how, "surrogatepass")
    return text.encode("utf-8", "surrogatepass")  # unescaped lone surrogates, if any


# Bytes to splice in: an encoded surrogate, a BOM, an overlong "/", past U+10FFFF, brackets.
SPLICES = [
    b"\xed\xa0\x80",
    b"\xef\xbb\xbf",
    b"\xc0\xaf",
    b"\xf4\x90\x80\x80",
    b"[",
    b"]",
    b"\\",
    b'"',
]


@st.composite
def mutated(draw, raw: bytes) -> bytes:
    """`raw` cut, with a byte flipped, or grown; or left as it is."""
    how = draw(st.sampled_from(["same", "same", "cut", "flip", "grow", "insert"]))
    if not raw or how == "same":
        return raw
    i = draw(st.integers(0, len(raw) - 1))
    if how == "cut":
        return raw[:i]
    if how == "flip":
        return raw[:i] + bytes([raw[i] ^ draw(st.integers(1, 255))]) + raw[i + 1 :]
    extra = draw(st.one_of(st.binary(max_size=8), st.sampled_from(SPLICES)))
    return raw + extra if how == "grow" else raw[:i] + extra + raw[i:]


@st.composite
def hostile_messages(draw) -> bytes:
    if draw(st.integers(0, 9)) == 0:
        return draw(st.binary(max_size=80))
    text = draw(message_texts())
    how = draw(st.sampled_from(["utf-8"] * 6 + ["bom", "surrogatepass", "utf-16", "utf-16-le",
                                                "utf-16-be", "utf-32", "utf-32-le"]))  # fmt: skip
    return draw(mutated(as_bytes(text, how)))


def assert_alike(data: bytes) -> None:
    py, cpp = py_decode(data), cpp_decode(data)
    assert (py is None) == (cpp is None), (data[:200], py, cpp)
    assert py is None or identical(py, cpp), (data[:200], py, cpp)


@SETTINGS
@given(data=hostile_messages())
@example(data=b"")
@example(data=b'{"k": "goal", "from": 3, "step": 1, "goal": [-0.0, -0], "cost": -0.0}')
@example(data=b'{"k": "replan", "from": true, "step": false, "goal": [true, 1e-400]}')
@example(data=b'{"k": "goal", "from": 3, "step": 1, "goal": [1, 2], "cost": 1, "n": null,'
              b' "fallback": "\\ud800"}')  # fmt: skip
def test_both_robots_decode_a_hostile_message_alike(data):
    assert_alike(data)


@SETTINGS
@given(text=message_texts())
def test_both_robots_decode_a_message_text_alike(text):
    """The texts on their own, in UTF-8: the fields' values are what is tested here, and
    most of these messages are accepted or refused for a field, not for their bytes."""
    assert_alike(text.encode("utf-8", "surrogatepass"))


@pytest.mark.parametrize("kind", ["[", "{"])
@pytest.mark.parametrize("inner", ["", "1"])
def test_the_nesting_bound_is_the_same_for_both(kind, inner):
    """64 objects and arrays one inside another (the message's own counted) decode; 65 do
    not; whatever holds the innermost."""
    for depth, accepted in ((63, True), (64, False)):
        data = ('{"k": "replan", "from": 2, "step": 1, "goal": [1, 2], "x": '
                + nested_value(depth, inner, kind)
                + "}").encode()  # fmt: skip
        assert (py_decode(data) is not None) == accepted, depth
        assert_alike(data)
