"""Files that other processes may read at any time, and that land in directories someone
else may have prepared: written whole or not at all, and never outside their directory.

The one atomic write and the one tolerant read of the project (run results, sweep state,
testbed state, the AODV daemons' statistics, the routing-metrics cache, and every report,
figure and table written into a results directory).

`write_atomic(path, data, root=...)` writes `data` to a temporary file next to `path`
(a fresh name, created with O_EXCL and O_NOFOLLOW) and renames it over `path`. Every
directory between `root` and `path` is opened with O_NOFOLLOW | O_DIRECTORY, one below the
other (openat), so a component that is a symbolic link or not a directory is refused (a
`UnsafeWrite`, one line, exit status 2) rather than followed: a results directory from
elsewhere whose `figures/` links to /etc cannot make the testbed write there. `root` itself
is the user's to name (it may be a link); without it, the file's own directory is the root.
A `path` that is a symbolic link is replaced, never written through.
"""

from __future__ import annotations

import errno
import json
import os
import secrets
import stat
from pathlib import Path
from typing import Any

from common import boundedfile
from common.errors import UsageError

_DIR_FLAGS = os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC | os.O_NONBLOCK


class UnsafeWrite(UsageError):
    """A write refused because its way into the directory passes a symbolic link or a
    file that is not a directory; str() is one line naming it."""


def _parts(path: Path, root: Path) -> tuple[str, ...]:
    """The components of `path` below `root` (ValueError when it is not below)."""
    rel = Path(os.path.normpath(path)).relative_to(os.path.normpath(root))
    if any(p in ("..", "") for p in rel.parts):
        raise ValueError(f"{path} is not inside {root}")
    return rel.parts


def _open_dirs(root: Path, parts: tuple[str, ...], create: bool) -> int:
    """A descriptor of root/parts[0]/..., each opened without following a link (made
    first, mode 0755, when `create`); UnsafeWrite for a link or a non-directory."""
    fd = os.open(root, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    try:
        for i, part in enumerate(parts):
            if create:
                try:
                    os.mkdir(part, 0o755, dir_fd=fd)
                except FileExistsError:
                    pass
            try:
                sub = os.open(part, _DIR_FLAGS, dir_fd=fd)
            except OSError as e:
                if e.errno in (errno.ELOOP, errno.ENOTDIR):
                    where = os.path.join(root, *parts[: i + 1])
                    raise UnsafeWrite(
                        f"{where}: a symbolic link or not a directory: nothing is written "
                        "through it"
                    ) from None
                raise
            os.close(fd)
            fd = sub
    except BaseException:
        os.close(fd)
        raise
    return fd


def make_dirs(path: str | os.PathLike[str], root: str | os.PathLike[str] | None = None) -> Path:
    """`path` as a directory below `root` (made where missing), every component a real
    directory, not a link (UnsafeWrite otherwise). Returns `path`."""
    path = Path(path)
    root = Path(root) if root is not None else path.parent
    root.mkdir(parents=True, exist_ok=True)  # the user's to name: made as asked
    os.close(_open_dirs(root, _parts(path, root), create=True))
    return Path(path)


def write_atomic(
    path: str | os.PathLike[str],
    data: bytes | str,
    *,
    root: str | os.PathLike[str] | None = None,
    mode: int = 0o644,
) -> None:
    """`path` holds `data` (str: UTF-8) or what it held before, never a part, and nothing
    outside `root` (default: path's directory) is written: see the module's docstring.
    `mode`: the file's permissions, whatever the umask."""
    path = Path(path)
    root = Path(root) if root is not None else path.parent
    if isinstance(data, str):  # a name that is not UTF-8 (a lone surrogate): as its escape
        data = data.encode(errors="backslashreplace")
    dfd = _open_dirs(root, _parts(path.parent, root), create=False)
    try:
        try:
            st = os.stat(path.name, dir_fd=dfd, follow_symlinks=False)
        except FileNotFoundError:
            st = None
        if st is not None and stat.S_ISDIR(st.st_mode):
            raise UnsafeWrite(f"{path}: a directory, not a file: not replaced")
        tmp = f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp"
        flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC
        fd = os.open(tmp, flags, mode, dir_fd=dfd)
        try:
            os.fchmod(fd, mode)
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view) :]
            os.close(fd)
            fd = -1
            os.replace(tmp, path.name, src_dir_fd=dfd, dst_dir_fd=dfd)
        except BaseException:
            if fd >= 0:
                os.close(fd)
            try:
                os.unlink(tmp, dir_fd=dfd)
            except OSError:
                pass
            raise
    finally:
        os.close(dfd)


def write_json_atomic(
    path: str | os.PathLike[str],
    obj: Any,
    *,
    sort_keys: bool = False,
    mode: int | None = None,
    root: str | os.PathLike[str] | None = None,
    strict: bool = False,
) -> None:
    """`path` holds `obj` (indent 1, newline-terminated) or what it held before, never a
    part (write_atomic). `mode`: the file's permissions (else 0644). `strict`: no NaN or
    Infinity (ValueError), for files other programs parse as JSON."""
    text = json.dumps(obj, indent=1, sort_keys=sort_keys, allow_nan=not strict) + "\n"
    write_atomic(path, text, root=root, mode=0o644 if mode is None else mode)


def read_json(path: str | os.PathLike[str]) -> Any:
    """The JSON in `path`, or None when it is missing, not a regular file (a FIFO is not
    waited on), too large, unreadable or not strict JSON (common.boundedfile.load_json)."""
    try:
        return boundedfile.load_json(path)
    except boundedfile.Refused:
        return None
