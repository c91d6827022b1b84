"""A fork server: Python programs started in robot namespaces without paying for their imports.

Theory of operation. A run starts a dozen Python processes (robots and the display) that all
import the same heavy modules (numpy, pynng, the node package): about 0.4 s of CPU each, which
on a 2-core machine is seconds of wall time per run before the first step. The fork server is
one process, started with `preload` modules imported and nothing else running (no threads,
no sockets but its control socket), that forks a child per request. The child enters the
robot's network namespace (setns on the /run/netns bind mount, as `ip netns exec` does; or
stays in the server's own, for `"ns": null`), gets its own session, its stdin from /dev/null
and its output into the given log file, the signal dispositions of a fresh interpreter
(SIGINT raises KeyboardInterrupt), optionally a parent-death signal, and calls the requested
module's `main(argv)`; its exit status is main's return value. Children share the imported
pages with the server until they write them.

The caller does not wait for the server's imports: `ForkServer()` returns at once and the
first `spawn` waits for "ready", so the imports overlap whatever the caller does meanwhile
(a run builds its network).

Protocol over a Unix socketpair, one JSON object per line:

    -> {"id": 1, "ns": "tb-x-r1", "module": "node.__main__", "argv": [...], "log": PATH,
        "env": {...}, "title": "r1 robot", "pdeathsig": 2}
    <- {"id": 1, "pid": 1234}            or {"id": 1, "error": "..."}
    <- {"exit": 1234, "status": 0}       when a child ends (negative: killed by that signal)

`ForkServer` is the caller's side; its `spawn` returns a `Forked`, which answers the parts of
`subprocess.Popen` a run uses (pid, poll, wait, returncode, send_signal). The server dies with
its parent (PR_SET_PDEATHSIG) and its children are recorded like any other testbed process,
so teardown and `testbed clean` stop them by pid.
"""

from __future__ import annotations

import ctypes
import importlib
import json
import os
import select
import signal
import socket
import subprocess
import sys
import time

from common.paths import PROJECT_ROOT
from topology.kernel import netns

_PR_SET_PDEATHSIG = 1
_PR_SET_NAME = 15
_libc = ctypes.CDLL(None, use_errno=True)


class ForkServerError(RuntimeError):
    pass


def python_env() -> dict[str, str]:
    """The environment for a fork server: this one, with this project importable."""
    env = dict(os.environ)
    env["PYTHONPATH"] = PROJECT_ROOT + (
        os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else ""
    )
    return env


# -- the server process --------------------------------------------------------------------


def _child(req: dict, ctl: socket.socket, server_pid: int) -> None:
    """In the forked child: become the requested program. Never returns."""
    status = 1
    try:
        ctl.close()
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        signal.signal(signal.SIGINT, signal.default_int_handler)
        signal.signal(signal.SIGCHLD, signal.SIG_DFL)
        os.setsid()
        if req.get("pdeathsig"):
            _libc.prctl(_PR_SET_PDEATHSIG, int(req["pdeathsig"]), 0, 0, 0)
            if os.getppid() != server_pid:  # the server died before prctl took effect
                os._exit(1)
        if req.get("title"):  # what ps -o comm and top show (the cmdline stays the server's)
            _libc.prctl(_PR_SET_NAME, req["title"].encode()[:15], 0, 0, 0)
        if req.get("ns"):
            netns.enter(req["ns"])
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        out = os.open(req["log"], os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
        os.dup2(out, 1)
        os.dup2(out, 2)
        os.environ.update(req.get("env") or {})
        sys.argv = [req["module"], *req["argv"]]
        main = importlib.import_module(req["module"]).main
        status = main(req["argv"]) or 0
    except SystemExit as e:
        status = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
    except BaseException:
        import traceback

        traceback.print_exc()
        status = 1
    finally:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
        finally:
            os._exit(status)


def serve(fd: int, preload: list[str], warm: list | None = None) -> int:
    """The server's loop: fork on request, report exits; ends when the caller hangs up.

    `preload` modules are imported first, then each (module, function, args) of `warm` is
    called: whatever they build is there in every child without being built again."""
    _libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
    _libc.prctl(_PR_SET_NAME, b"forkserver", 0, 0, 0)
    for module in preload:
        importlib.import_module(module)
    for module, function, args in warm or []:
        getattr(importlib.import_module(module), function)(*args)
    ctl = socket.socket(fileno=fd)
    try:
        return _loop(ctl)
    except (BrokenPipeError, ConnectionResetError):
        return 0  # the caller hung up, perhaps before it ever asked for anything


def _loop(ctl: socket.socket) -> int:
    buf = b""
    children: set[int] = set()

    def reply(obj: dict) -> None:
        ctl.sendall(json.dumps(obj).encode() + b"\n")

    server_pid = os.getpid()
    reply({"ready": server_pid})
    while True:
        ready, _, _ = select.select([ctl], [], [], 0.05)
        if ready:
            try:
                data = ctl.recv(65536)
            except OSError:
                data = b""
            if not data:
                return 0
            buf += data
            while b"\n" in buf:
                line, buf = buf.split(b"\n", 1)
                req = json.loads(line)
                try:
                    if req.get("ns") and not os.path.exists(netns.path(req["ns"])):
                        raise ForkServerError(f"no network namespace {req['ns']}")
                    pid = os.fork()
                except (OSError, ForkServerError) as e:
                    reply({"id": req["id"], "error": str(e)})
                    continue
                if pid == 0:
                    _child(req, ctl, server_pid)
                children.add(pid)
                reply({"id": req["id"], "pid": pid})
        while children:
            try:
                pid, st = os.waitpid(-1, os.WNOHANG)
            except ChildProcessError:
                break
            if pid == 0:
                break
            children.discard(pid)
            reply({"exit": pid, "status": os.waitstatus_to_exitcode(st)})


# -- the caller's side ---------------------------------------------------------------------


class Forked:
    """A child of the fork server, with the parts of Popen's interface a run uses."""

    def __init__(self, server: ForkServer, pid: int):
        self.server = server
        self.pid = pid
        self.returncode: int | None = None

    def poll(self) -> int | None:
        if self.returncode is None:
            self.server.collect(0.0)
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        deadline = None if timeout is None else time.monotonic() + timeout
        while (code := self.poll()) is None:
            left = 0.1 if deadline is None else deadline - time.monotonic()
            if left <= 0 and timeout is not None:  # (only with a deadline)
                raise subprocess.TimeoutExpired(f"pid {self.pid}", timeout)
            self.server.collect(min(0.1, left))
        return code

    def send_signal(self, sig: int) -> None:
        if self.returncode is None:
            os.kill(self.pid, sig)

    def terminate(self) -> None:
        self.send_signal(signal.SIGTERM)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)


class ForkServer:
    """Starts the server with `preload` imported and `warm` calls made (see serve); `spawn`
    forks programs from it."""

    def __init__(
        self,
        preload: list[str],
        env: dict | None = None,
        warm: list | None = None,
        label: str = "",
    ):
        ours, theirs = socket.socketpair()
        code = (
            "import sys, json; from topology.kernel.forkserver import serve; "
            f"sys.exit(serve({theirs.fileno()}, {preload!r}, json.loads({json.dumps(warm)!r})))"
        )
        self.proc = subprocess.Popen(
            # `label` (e.g. the run's directory) is in the command line of the server and of
            # every child, for ps and for finding a run's processes.
            [sys.executable, "-c", code] + ([label] if label else []),
            pass_fds=(theirs.fileno(),),
            stdin=subprocess.DEVNULL,
            env=env,
            start_new_session=True,
        )
        theirs.close()
        self.ctl = ours
        self.buf = b""
        self.next_id = 0
        self.children: dict[int, Forked] = {}
        self.replies: dict[int, dict] = {}
        self.ready = False

    def wait_ready(self, timeout: float = 60.0) -> None:
        """Block until the server has done its imports (spawn calls this)."""
        if self.ready:
            return
        try:
            msg = self._read(timeout, lambda m: "ready" in m)
        except ForkServerError:
            msg = None
        if msg is None:
            raise ForkServerError("the fork server did not start")
        self.ready = True

    def _read(self, timeout: float, want) -> dict | None:
        """Read messages until one satisfies `want` (returned) or the timeout passes."""
        deadline = time.monotonic() + timeout
        while True:
            while b"\n" in self.buf:
                line, self.buf = self.buf.split(b"\n", 1)
                msg = json.loads(line)
                if "exit" in msg:
                    child = self.children.get(msg["exit"])
                    if child is not None:
                        child.returncode = msg["status"]
                elif "id" in msg:
                    self.replies[msg["id"]] = msg
                if want(msg):
                    return msg
            left = max(0.0, deadline - time.monotonic())  # 0: look without waiting
            ready, _, _ = select.select([self.ctl], [], [], left)
            if not ready:
                return None
            data = self.ctl.recv(65536)
            if not data:
                raise ForkServerError("the fork server died")
            self.buf += data

    def collect(self, timeout: float) -> None:
        """Take in the exit reports that have arrived (waiting at most `timeout`)."""
        self._read(timeout, lambda m: False)

    def spawn(
        self,
        ns: str | None,
        module: str,
        argv: list[str],
        log: str,
        env=None,
        title: str = "",
        pdeathsig: int = 0,
    ) -> Forked:
        """Fork `module.main(argv)` in namespace `ns` (None: the server's), output appended to
        `log`; `title` (at most 15 characters) is the process name that ps and top show;
        `pdeathsig`, if given, is the signal the child gets when the server dies."""
        self.wait_ready()
        self.next_id += 1
        rid = self.next_id
        req = {"id": rid, "ns": ns, "module": module, "argv": argv, "log": log, "env": env,
               "title": title, "pdeathsig": int(pdeathsig)}  # fmt: skip
        self.ctl.sendall(json.dumps(req).encode() + b"\n")
        msg = self.replies.pop(rid, None) or self._read(30.0, lambda m: m.get("id") == rid)
        self.replies.pop(rid, None)
        if msg is None:
            raise ForkServerError(f"the fork server did not answer for {module} in {ns}")
        if "error" in msg:
            raise ForkServerError(f"cannot start {module} in {ns}: {msg['error']}")
        child = Forked(self, msg["pid"])
        self.children[child.pid] = child
        return child

    def close(self) -> None:
        """Hang up: the server exits (its children live on until they are stopped)."""
        try:
            self.ctl.close()
        finally:
            try:
                self.proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
