"""The robots' unicast messages (goals, re-plan requests) over a choice of middleware.

Theory of operation. Each middleware is one module of this package with one class that
keeps the messenger contract (node.messaging.contract; docs/middleware.md says what each
does here). The registry below is the one list of the middlewares: for each, that module,
its class, the Python package it needs, how its messages are framed on the wire (what the
capture analysis parses) and, for those that publish maps (`--maps pubsub`), the module of its
map topic. MIDDLEWARES, node.messaging.maps' tables and testbed.analysis.mwtraffic's are made
from it. `open_messenger(name, **kwargs)` imports the module only when
it is asked for, so a robot loads its own middleware and nothing else, and a package that
is not installed is a `MiddlewareUnavailable` whose message names the package to install.
`unavailable(name)` says the same without opening anything: what a run checks before it
makes its namespaces, and what the tests use to skip a middleware this machine lacks.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from node.messaging.contract import Messenger


@dataclass(frozen=True)
class Entry:
    """Where a middleware's messenger lives and what it needs."""

    module: str  # this package's module holding the class
    cls: str  # the messenger class
    imports: str  # the top-level module its Python package provides
    package: str  # that package's name on PyPI (pinned in pyproject.toml's middleware extra)
    # How its messages look on the goal port (testbed.analysis.mwframing, testbed.analysis.rtps):
    # sp, zmtp, zenoh over TCP; rtps over UDP.
    framing: str
    map_topic: str | None = None  # the module of its map topic (node.messaging.maps), if any


REGISTRY: dict[str, Entry] = {
    "nanomsg": Entry("node.messaging.nanomsg", "NanomsgMessenger", "pynng", "pynng", "sp"),
    "zeromq": Entry("node.messaging.zeromq", "ZeroMQMessenger", "zmq", "pyzmq", "zmtp"),
    "zeromq-reqrep": Entry(
        "node.messaging.zeromq_reqrep", "ZeroMQReqRepMessenger", "zmq", "pyzmq", "zmtp"
    ),  # fmt: skip
    "zenoh": Entry("node.messaging.zenoh", "ZenohMessenger", "zenoh", "eclipse-zenoh", "zenoh",
                   map_topic="node.messaging.zenoh_maps"),
    "dds": Entry("node.messaging.dds", "DdsMessenger", "cyclonedds", "cyclonedds", "rtps",
                 map_topic="node.messaging.dds_maps"),
}  # fmt: skip
MIDDLEWARES = tuple(REGISTRY)
DEFAULT = "nanomsg"
DEFAULT_MAPS = "flood"  # how maps are shared (node.messaging.maps.DEFAULT)
# Messages queued per teammate: nanomsg's send_buffer_size, ZeroMQ's SNDHWM (both robots).
SEND_QUEUE = 8


class MiddlewareUnavailable(Exception):
    """A middleware this machine (or this testbed) cannot open; the message is one line."""


def _entry(name: str) -> Entry:
    entry = REGISTRY.get(name)
    if entry is None:
        raise MiddlewareUnavailable(
            f"--middleware {name!r}: unknown (one of {', '.join(MIDDLEWARES)})"
        )
    return entry


def messenger_class(name: str) -> type:
    """The messenger class of middleware `name`, its module imported now;
    MiddlewareUnavailable when its package is missing (tests/unit/test_messaging.py holds
    that every entry's module and class exist)."""
    entry = _entry(name)
    try:
        importlib.import_module(entry.imports)
    except ImportError as e:
        why = "is not installed" if isinstance(e, ModuleNotFoundError) else f"does not load: {e}"
        raise MiddlewareUnavailable(
            f"--middleware {name} needs the Python package {entry.package}, which {why} "
            f"(`make setup` installs it, or: pip install {entry.package})"
        ) from None
    return getattr(importlib.import_module(entry.module), entry.cls)


def unavailable(name: str) -> str | None:
    """Why middleware `name` cannot be opened here (one line), or None when it can."""
    try:
        messenger_class(name)
    except MiddlewareUnavailable as e:
        return str(e)
    return None


def module_of(name: str) -> str:
    """The module of middleware `name` (what a process may import ahead of opening it)."""
    return _entry(name).module


def open_messenger(name: str, **kwargs) -> Messenger:
    """A messenger of middleware `name`, made with the contract's arguments `kwargs`;
    MiddlewareUnavailable (one line naming what is missing) when it cannot be."""
    return messenger_class(name)(**kwargs)
