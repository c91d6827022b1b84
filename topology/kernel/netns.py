"""Named network namespaces, created and entered without forking.

`ip netns add` and pyroute2's `netns.create` fork a process per namespace; with 50 robots that
alone would eat the bring-up budget. Linux keeps the network namespace per *thread*, so this
module does the same work in short-lived threads: a thread unshares a new namespace and
bind-mounts it at /run/netns/NAME (exactly where iproute2 looks, so `ip netns exec` works on
our namespaces), or a thread setns()es into an existing one and runs a function there.

`NsWorker` is a long-lived thread parked in one namespace with its own pyroute2 IPRoute:
callers hand it functions and get results back. pyroute2 0.9 keeps one netlink socket per
thread, which is why the socket must be made and used in the worker thread itself.

Subprocesses inherit the namespace of the thread that forks them; `popen_argv` uses
`ip netns exec` instead, which also gives the child the namespace's own /sys view, except
for a program that enters the namespace itself (`EnteringArgv`: its first option is
`--netns NAME`, as the AODV daemons take it). `ip netns exec` is a fork and exec of ip and a
mount namespace of its own per child (its /sys remounted): 3.7 of the 8.3 s that starting
1,000 AODV daemons took, for a daemon that reads no /sys.
"""

import ctypes
import errno
import os
import queue
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from pyroute2 import IPRoute

NETNS_DIR = "/run/netns"
CLONE_NEWNET = 0x40000000
MS_REC = 0x4000
MS_BIND = 0x1000
MS_SHARED = 1 << 20
MNT_DETACH = 2

_libc = ctypes.CDLL(None, use_errno=True)
_rundir_ready = threading.Lock()
_rundir_shared = False


def _check(ret: int, what: str, path: str) -> None:
    if ret != 0:
        err = ctypes.get_errno()
        raise OSError(err, f"{what} {path}: {os.strerror(err)}")


def _share_rundir() -> None:
    """Make /run/netns a shared mount point, as iproute2 does, so our binds propagate."""
    global _rundir_shared
    with _rundir_ready:
        if _rundir_shared:
            return
        os.makedirs(NETNS_DIR, exist_ok=True)
        d = NETNS_DIR.encode()
        if _libc.mount(b"", d, b"none", MS_SHARED | MS_REC, None) != 0:
            _check(_libc.mount(d, d, b"none", MS_BIND | MS_REC, None), "bind-mount", NETNS_DIR)
            _check(_libc.mount(b"", d, b"none", MS_SHARED | MS_REC, None), "share", NETNS_DIR)
        _rundir_shared = True


def path(name: str) -> str:
    return os.path.join(NETNS_DIR, name)


def exists(name: str) -> bool:
    return os.path.exists(path(name))


def list_names() -> list[str]:
    try:
        return sorted(os.listdir(NETNS_DIR))
    except FileNotFoundError:
        return []


def _in_thread(fn: Callable[[], Any]) -> Any:
    box: dict[str, Any] = {}

    def run() -> None:
        try:
            box["value"] = fn()
        except BaseException as exc:  # re-raised in the caller's thread
            box["error"] = exc

    t = threading.Thread(target=run, name="netns")
    t.start()
    t.join()
    if "error" in box:
        raise box["error"]
    return box.get("value")


def create(name: str) -> None:
    """Create the named namespace; raise FileExistsError if the name is taken."""
    _share_rundir()
    target = path(name)
    os.close(os.open(target, os.O_RDONLY | os.O_CREAT | os.O_EXCL, 0))

    def unshare_and_bind() -> None:
        _check(_libc.unshare(CLONE_NEWNET), "unshare for", target)
        me = f"/proc/self/task/{threading.get_native_id()}/ns/net".encode()
        _check(_libc.mount(me, target.encode(), b"none", MS_BIND, None), "bind", target)

    try:
        _in_thread(unshare_and_bind)
    except BaseException:
        os.unlink(target)
        raise


def remove(name: str) -> bool:
    """Unmount and unlink the named namespace; False if it was already gone."""
    target = path(name)
    if not os.path.exists(target):
        return False
    if _libc.umount2(target.encode(), MNT_DETACH) != 0:
        err = ctypes.get_errno()
        if err not in (errno.EINVAL, errno.ENOENT):  # EINVAL: not mounted (half-made)
            raise OSError(err, f"umount {target}: {os.strerror(err)}")
    try:
        os.unlink(target)
    except FileNotFoundError:
        return False
    return True


def enter(name: str) -> None:
    """Move the calling thread into namespace `name` (a single-threaded process moves whole:
    that is how the fork server's children enter theirs)."""
    _enter(name)


def _enter(name: str) -> None:
    fd = os.open(path(name), os.O_RDONLY)
    try:
        _check(_libc.setns(fd, CLONE_NEWNET), "setns", path(name))
    finally:
        os.close(fd)


def run_in(name: str, fn: Callable[[], Any]) -> Any:
    """Run fn() in a fresh thread inside namespace `name` and return its result."""

    def entered() -> Any:
        _enter(name)
        return fn()

    return _in_thread(entered)


def run_in_each(names_: list[str], fn: Callable[[str], Any]) -> list[Any]:
    """Run fn(name) inside each namespace in turn, all in one thread; return the results."""

    def visit() -> list[Any]:
        out = []
        for name in names_:
            _enter(name)
            out.append(fn(name))
        return out

    return _in_thread(visit)


def write_sysctl(key: str, value: str | int) -> None:
    """Write a sysctl in the calling thread's namespace (key like 'net.ipv4.ip_forward')."""
    with open("/proc/sys/" + key.replace(".", "/"), "w") as f:
        f.write(str(value))


class EnteringArgv(list[str]):
    """The argv of a program that enters namespace `netns` itself, given `--netns NAME` as its
    first option (before it makes any socket): popen_argv runs it as it is. A type of its
    own, so that no other command line is taken for one by its look."""

    def __init__(self, name: str, program: str, args: list[str]):
        super().__init__([program, "--netns", name, *args])
        self.netns = name


def popen_argv(name: str, argv: list[str]) -> list[str]:
    """The argv that runs `argv` inside namespace `name` (the pid stays that of argv): argv
    itself if it enters `name` on its own (EnteringArgv), else under `ip netns exec`."""
    if isinstance(argv, EnteringArgv) and argv.netns == name:
        return list(argv)
    return ["ip", "netns", "exec", name, *argv]


_STOP = object()


class NsWorker:
    """A thread parked in one namespace, with an IPRoute of its own, running submitted calls.

    `nl` is a raw rtnetlink socket of that namespace (topology.kernel.rtnl), usable from any thread:
    a socket belongs to the namespace it was made in."""

    def __init__(self, name: str):
        self.name = name
        self._jobs: queue.Queue = queue.Queue()
        ready: queue.Queue = queue.Queue()
        self._thread = threading.Thread(
            target=self._loop, args=(ready,), name=f"ns:{name}", daemon=True
        )
        self._thread.start()
        error = ready.get()
        if error is not None:
            self._thread.join()
            raise error

    def _loop(self, ready: queue.Queue) -> None:
        # pyroute2 is imported here, not at the top: it takes 0.2 s, and the fork servers
        # (topology.kernel.forkserver), which only enter namespaces, start without it.
        from pyroute2 import IPRoute

        from topology.kernel import rtnl

        try:
            _enter(self.name)
            ipr = IPRoute()
            self.nl = rtnl.open_socket()
        except BaseException as exc:
            ready.put(exc)
            return
        ready.put(None)
        try:
            while True:
                job = self._jobs.get()
                if job is _STOP:
                    return
                fn, reply = job
                try:
                    reply.put((True, fn(ipr)))
                except BaseException as exc:
                    reply.put((False, exc))
        finally:
            ipr.close()
            self.nl.close()

    def call(self, fn: Callable[["IPRoute"], Any]) -> Any:
        """Run fn(ipr) in the namespace and return its result (or raise its exception)."""
        reply: queue.Queue = queue.Queue(maxsize=1)
        self._jobs.put((fn, reply))
        ok, value = reply.get()
        if not ok:
            raise value
        return value

    def close(self) -> None:
        """Stop the thread; it holds a reference to the namespace until it exits."""
        if self._thread.is_alive():
            self._jobs.put(_STOP)
            self._thread.join()
