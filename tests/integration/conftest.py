"""Integration tests: real namespaces, root only, nothing left behind.

Every test gets a unique testbed name from `tb_name`. The session checks at the end that the
host namespace's interfaces, routes and nftables ruleset are as they were at the start, and
that no namespace of a testbed made by this session is left.
"""

import os
import shutil
import subprocess
import uuid

import pytest

from topology import names
from topology.kernel import netns

SESSION_TAG = uuid.uuid4().hex[:3]
_made: list[str] = []


NEED_ROOT = "integration tests need root (network namespaces): run `sudo make test`"
_skipped: list[str] = []


def pytest_collection_modifyitems(config, items):
    """Not root: a session of integration tests only stops at once with NEED_ROOT (exit
    status 2, not a green run of skips); in a wider session (`pytest` over every test
    folder) they are skipped, and the summary says so in that one line."""
    if os.geteuid() == 0:
        return
    integration = [item for item in items if "integration" in str(item.fspath)]
    if integration and len(integration) == len(items):
        pytest.exit(NEED_ROOT, returncode=2)
    skip = pytest.mark.skip(reason=NEED_ROOT)
    for item in integration:
        item.add_marker(skip)
        _skipped.append(item.nodeid)


def pytest_terminal_summary(terminalreporter):
    if _skipped:
        terminalreporter.write_line(f"{len(_skipped)} skipped: {NEED_ROOT}", yellow=True)


def _host_snapshot() -> dict[str, str]:
    def run(argv: list[str]) -> str:
        return subprocess.run(argv, capture_output=True, text=True).stdout

    links = run(["ip", "-o", "link", "show"])
    return {
        # interface names and flags, not counters
        "links": "\n".join(sorted(line.split("link/")[0] for line in links.splitlines())),
        "routes": run(["ip", "route", "show", "table", "all"]),
        "rules": run(["ip", "rule", "show"]),
        "addrs": run(["ip", "-o", "addr", "show"]),
        "nft": run(["nft", "list", "ruleset"]) if shutil.which("nft") else "",
    }


@pytest.fixture(scope="session", autouse=True)
def host_untouched():
    if os.geteuid() != 0:
        yield
        return
    before = _host_snapshot()
    yield
    after = _host_snapshot()
    changed = [k for k in before if before[k] != after[k]]
    leftover = [ns for ns in netns.list_names() if (names.parse_ns(ns) or ("",))[0] in _made]
    assert not leftover, f"namespaces left behind: {leftover}"
    assert not changed, f"the host namespace changed: {changed}"


@pytest.fixture
def tb_name() -> str:
    """A testbed name unique to this test (prefix 'it': integration tests of topology)."""
    name = f"it{SESSION_TAG}{uuid.uuid4().hex[:5]}"
    _made.append(name)
    yield name
    # Whatever the test did, nothing of this name survives it.
    from topology.network import destroy

    destroy(name)


@pytest.fixture
def small_map(tmp_path):
    """An empty 10 x 10 m map (100 x 100 cells of 0.1 m), for short runs."""
    import cv2
    import numpy as np

    path = tmp_path / "small.png"
    cv2.imwrite(str(path), np.full((100, 100), 255, dtype=np.uint8))  # 10 x 10 m, no walls
    return str(path)


@pytest.fixture(params=["python", "cpp"])
def aodv_daemon(request) -> str:
    """Which AODV daemon the test runs: every daemon test runs against both, the Python
    reference (`python -m aodv`) and the compiled one (build/tb-aodv; topology.routing). The
    compiled one is skipped only where `make setup` could not build it, with its one line
    (build/tb-aodv.unbuilt); where it was to be built, its absence fails the test."""
    from topology import routing

    if request.param == "cpp" and not routing.aodv_built():
        why = routing.aodv_unbuilt_reason()
        if why:
            pytest.skip(why)
        pytest.fail(
            f"{routing.aodv_binary()} is not there and {routing.TB_AODV_UNBUILT} does not say "
            "why: run `make setup`"
        )
    return request.param
