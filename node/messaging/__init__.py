"""The robots' unicast messages (goals, re-plan requests) over a choice of middleware.

Theory of operation. Each middleware is one module of this package with one class that
keeps the messenger contract (node.messaging.contract; docs/middleware.md says what each
does here). The registry below names, for each of MIDDLEWARES, that module, its class and
the Python package it needs. `open_messenger(name, **kwargs)` imports the module only when
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

MIDDLEWARES = ("nanomsg", "zeromq", "zeromq-reqrep", "zenoh", "dds")
DEFAULT = "nanomsg"


@dataclass(frozen=True)
class Entry:
    """Where a middleware's messenger lives and what it needs."""

    module: str  # this package's module holding the class
    cls: str  # the messenger class
    imports: str  # the top-level module its Python package provides
    package: str  # that package's name on PyPI (pinned in pyproject.toml's middleware extra)


REGISTRY: dict[str, Entry] = {
    "nanomsg": Entry("node.messaging.nanomsg", "NanomsgMessenger", "pynng", "pynng"),
    "zeromq": Entry("node.messaging.zeromq", "ZeroMQMessenger", "zmq", "pyzmq"),
    "zeromq-reqrep": Entry(
        "node.messaging.zeromq_reqrep", "ZeroMQReqRepMessenger", "zmq", "pyzmq"
    ),  # fmt: skip
    "zenoh": Entry("node.messaging.zenoh", "ZenohMessenger", "zenoh", "eclipse-zenoh"),
    "dds": Entry("node.messaging.dds", "DdsMessenger", "cyclonedds", "cyclonedds"),
}


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
    MiddlewareUnavailable when its package is missing or its module not part of this
    testbed."""
    entry = _entry(name)
    try:
        importlib.import_module(entry.imports)
    except ImportError as e:
        why = "is not installed" if isinstance(e, ModuleNotFoundError) else f"does not load: {e}"
        raise MiddlewareUnavailable(
            f"--middleware {name} needs the Python package {entry.package}, which {why} "
            f"(`make setup` installs it, or: pip install {entry.package})"
        ) from None
    try:
        module = importlib.import_module(entry.module)
    except ModuleNotFoundError as e:
        if e.name != entry.module:
            raise
        raise MiddlewareUnavailable(
            f"--middleware {name}: this testbed has no {entry.module} (not written yet)"
        ) from None
    try:
        return getattr(module, entry.cls)
    except AttributeError:
        raise MiddlewareUnavailable(
            f"--middleware {name}: {entry.module} has no class {entry.cls}"
        ) from None


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
