"""The routing protocols' registry (topology.protocols): every table that names protocols is
made from it, and an entry that lacks what a table needs fails as it is made.

Theory: each view is checked against the registry itself (not a copy of today's list), so a
protocol added to the registry is checked in every view, and a view that went back to a table
of its own would miss or disagree with the new entry. The Makefile's apt lists are read as
text: a protocol's package there is what `make setup` installs.
"""

import ast
import os
import re
import sys

import pytest

from common.paths import PROJECT_ROOT
from testbed.analysis import framecounts, protocols
from testbed.bench import cost
from topology import bringup, routing, spec
from topology.protocols import REGISTRY, ROUTINGS, Daemon, Protocol, _registry

# Packages of Debian's priority "required" (always there), which setup need not install.
ESSENTIAL = {"util-linux"}


def _net_spec(routing_name: str, **kw) -> spec.NetworkSpec:
    return spec.NetworkSpec("t", ((0.0, 0.0), (5.0, 0.0)), 10.0, routing=routing_name, **kw)


def test_every_protocol_is_in_every_view():
    names = list(REGISTRY)
    assert list(ROUTINGS) == list(spec.ROUTINGS) == names and ROUTINGS[0] == "aodv"
    assert set(routing.PROTOCOLS) == set(routing.REQUIRED_TOOLS) == set(names)
    assert set(framecounts.CONTROL_PORTS) == set(names)
    for p in REGISTRY.values():
        assert framecounts.CONTROL_PORTS[p.name] == p.control_port
        assert (p.name in protocols.PROACTIVE) == p.proactive
        assert routing.has_daemon(p.name) == (p.daemon is not None)
        _net_spec(p.name)  # the spec takes every registered protocol
        if p.daemon is None:
            assert routing.PROTOCOLS[p.name] is None
            assert routing.argv_for(_net_spec(p.name), 1, "/run/x") is None
            assert routing.stats_file(p.name, 1, "/run/x") is None
            continue
        argv = routing.argv_for(_net_spec(p.name), 2, "/run/x")
        assert argv and all(isinstance(a, str) for a in argv)
        assert routing.REQUIRED_TOOLS[p.name] == list(p.daemon.tools)
        assert set(p.daemon.programs) <= set(cost.ROUTING_PROGRAMS)
        assert f" {p.name}" in cost.ROUTING_TITLES
        if p.daemon.forkable:
            assert routing.FORKABLE[p.name] is p.daemon.forkable
            assert routing.fork_args(_net_spec(p.name), 2, "/run/x")
        for pattern in (p.daemon.ready_file, p.daemon.stats_file):
            assert pattern is None or "{k}" in pattern
    assert routing.aodv_stats_file(3, "/run/x") == "/run/x/r3.aodv.json"
    assert routing.ready_file("aodv", 3, "/run/x") == "/run/x/r3.aodv.json"


def test_unknown_routing_is_refused_by_the_spec():
    with pytest.raises(ValueError, match="unknown routing 'olsr'"):
        _net_spec("olsr")


def test_a_protocol_without_its_control_port_cannot_be_registered():
    with pytest.raises(TypeError):
        Protocol("olsr", daemon=None)  # type: ignore[call-arg]
    for port in (None, 0, 70000, "698", True):
        with pytest.raises(ValueError, match="control port"):
            Protocol("olsr", port, daemon=None)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="registered twice"):
        _registry(Protocol("x", 698, None), Protocol("x", 699, None))
    with pytest.raises(ValueError, match="names no argv builder"):
        Protocol("olsr", 698, Daemon(argv=""))


def test_an_argv_builder_that_is_not_there_fails_at_import():
    p = Protocol("olsr", 698, Daemon(argv="olsr_argv"))
    with pytest.raises(ImportError, match="olsr_argv"):
        routing._builder(p, "olsr_argv")


def test_the_daemon_tools_packages_are_what_setup_installs():
    with open(os.path.join(PROJECT_ROOT, "Makefile")) as f:
        text = f.read().replace("\\\n", " ")
    apt = set(re.search(r"^APT_PACKAGES := (.*)$", text, re.M).group(1).split())
    for p in REGISTRY.values():
        for tool, package in (p.daemon.tools if p.daemon else {}).items():
            assert package in apt | ESSENTIAL, f"{p.name}: {tool}'s package {package}"
            assert routing.tool_packages(p.name)[tool] == package
    assert not set(bringup.TOOL_PACKAGES) & {t for p in REGISTRY.values() if p.daemon
                                             for t in p.daemon.tools}  # fmt: skip


def test_the_registry_module_is_data_only():
    """The analysis imports it: it must not pull in what runs a testbed."""
    path = sys.modules[Protocol.__module__].__file__
    assert path is not None
    with open(path) as f:
        tree = ast.parse(f.read())
    imported = {
        (n.module or "") if isinstance(n, ast.ImportFrom) else a.name
        for n in ast.walk(tree)
        if isinstance(n, ast.Import | ast.ImportFrom)
        for a in n.names
    }
    assert imported <= {"__future__", "dataclasses"}


def test_keep_daemon_files_keeps_statistics_only_where_the_protocol_writes_them(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    for name in ("r1.babel.log", "r1.babel.json", "r1.aodv.log", "r1.aodv.json"):
        (run / name).write_text("{}")
    for name in ("babel", "aodv"):
        routing.keep_daemon_files(name, [1], str(run), str(tmp_path / "logs"),
                                  str(tmp_path / name))  # fmt: skip
    assert (tmp_path / "logs" / "r1.babel.log").exists()
    assert not (tmp_path / "babel").exists()
    assert (tmp_path / "aodv" / "r1.json").exists()
