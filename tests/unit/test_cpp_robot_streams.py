"""The C++ robot writes no C++ stream while it runs (its logs and events go through stdio):
the ThreadSanitizer suppressions of its ZeroMQ runs (tests/integration/tsan-libzmq.supp) take
every race in std::basic_streambuf to be libzmq's, which holds only while this does."""

import re
from pathlib import Path

NATIVE = Path(__file__).resolve().parents[2] / "native"
STREAM_HEADER = re.compile(r"#\s*include\s*<(iostream|sstream|fstream|ostream|istream)>")
SELF_TEST = "selftest.cc"  # tb-robot --decode/--encode: the contract's self-test, never a run


def test_only_the_self_test_includes_a_stream_header():
    found = sorted(
        p.name
        for p in (NATIVE / "robot").iterdir()
        if p.suffix in (".cc", ".h") and STREAM_HEADER.search(p.read_text())
    )
    assert found == [SELF_TEST]
    for p in (NATIVE / "stepcore").iterdir():
        assert not STREAM_HEADER.search(p.read_text()), p


def test_the_suppression_says_why_it_holds():
    supp = (Path(__file__).resolve().parents[1] / "integration" / "tsan-libzmq.supp").read_text()
    assert "race:std::basic_streambuf" in supp and "test_cpp_robot_streams.py" in supp
