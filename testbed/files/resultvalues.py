"""Checked reading of the testbed's JSON records (result.json and its parts, and the files
read like it): a value of the kinds a key must have, or a `ResultError` of one line naming
the key; strings made one line (`one_line`), so that no report or terminal takes a stored
string as markup; and `plain`, a record's values as JSON holds them."""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Any, TypeVar

from common import boundedfile

EMPTY: Mapping[str, Any] = MappingProxyType({})
NUM = (int, float)


class ResultError(ValueError):
    """A result.json that cannot be read as one; str() is one line (naming the file when
    it was read from one)."""


def one_line(text: str, limit: int = 500) -> str:
    """`text` as one printable line: a control character (newline, ESC, ...) shown as its
    Python escape, so that neither a report's markdown nor a terminal takes it as markup;
    at most `limit` characters (an ellipsis marks the cut)."""
    out = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)
    return out if len(out) <= limit else out[: limit - 1] + "…"


def one_lines(value: Any) -> Any:
    """A record's strings, nested ones included, each made one line (one_line)."""
    if isinstance(value, str):
        return one_line(value)
    if isinstance(value, Mapping):
        return {one_line(str(k)): one_lines(v) for k, v in value.items()}
    if isinstance(value, list):
        return [one_lines(v) for v in value]
    return value


def get_value(
    doc: Mapping[str, Any],
    key: str,
    kinds: tuple[type, ...],
    default: Any = None,
    required: bool = False,
) -> Any:
    """doc[key] checked against `kinds` (bool is not a number); default when absent or null."""
    value = doc.get(key)
    if value is None:
        if required:
            raise ResultError(f"no {key!r}")
        return default
    number = kinds in ((int,), NUM)
    if not isinstance(value, kinds) or (number and isinstance(value, bool)):
        want = " or ".join(k.__name__ for k in kinds)
        raise ResultError(f"{key!r} is {type(value).__name__}, not {want}")
    return one_line(value) if isinstance(value, str) else value


def get_mapping(doc: Mapping[str, Any], key: str) -> Mapping[str, Any]:
    value = doc.get(key)
    if value is None:
        return EMPTY
    if not isinstance(value, Mapping):
        raise ResultError(f"{key!r} is {type(value).__name__}, not an object")
    return MappingProxyType(one_lines(dict(value)))


def get_list(doc: Mapping[str, Any], key: str) -> list[Any]:
    value = doc.get(key)
    if value is None:
        return []
    if not isinstance(value, list):
        raise ResultError(f"{key!r} is {type(value).__name__}, not a list")
    return value


def plain(value: Any) -> Any:
    """A value as JSON holds it: mappings as dicts, tuples as lists, dataclasses by to_dict."""
    if hasattr(value, "to_dict"):
        return value.to_dict()
    if isinstance(value, Mapping):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    return value


T = TypeVar("T")


def read_json_as(path: str | os.PathLike[str], parse: Callable[[Any], T]) -> T:
    """The JSON file at `path` (read bounded, a FIFO refused) through `parse`; ResultError,
    one line naming the file, when it cannot be read or `parse` refuses it."""
    try:
        doc = boundedfile.load_json(path)
    except boundedfile.Refused as r:
        raise ResultError(f"{path}: {boundedfile.describe(r)}") from None
    try:
        return parse(doc)
    except ResultError as e:
        raise ResultError(f"{path}: {e}") from None
