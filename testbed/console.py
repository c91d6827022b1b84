"""The `testbed` command's entry point: the console script calls `main` here.

It holds nothing but a guard around importing the command (testbed.cli), which takes about
half a second (numpy, OpenCV, pyroute2): a Ctrl-C in that time is one line and exit status
130, like a Ctrl-C at any later moment (testbed.cli.main handles those), instead of a
traceback of whichever import it interrupted. Nothing exists yet to be cleaned up then.

A Ctrl-C during the imports is noted and acted on once they are done (raised there, it could
land in a weakref callback an import runs, where Python reports it as ignored and goes on).
The guard starts when `main` is called. Before that the interpreter starts and runs the
console script's own imports (about 20 ms on a quiet machine, longer on a loaded one); a
Ctrl-C in that time is Python's: it ends the process by SIGINT, with a traceback if Python's
handler was installed by then. A launcher that blocks SIGINT while it starts the command
(`env --block-signal=INT testbed ...`) closes that window: `main` unblocks it first, inside
the guard, so a Ctrl-C that came during the start is taken there.
"""

import signal
import sys

EXIT_INTERRUPTED = 130


def main() -> int:
    try:
        # During the imports a Ctrl-C is noted, not raised: raised, it may land in a weakref
        # callback that an import runs (importlib's module locks are weakly held), where
        # Python reports it as "Exception ignored" and goes on, and the Ctrl-C is lost.
        noted: list[int] = []
        python_handler = signal.getsignal(signal.SIGINT)
        # Noted even where the launcher left it ignored (a script's `&` does): testbed.cli
        # takes SIGINT whatever was inherited (None: a handler not set from Python).
        noting = python_handler is not None
        if noting:
            signal.signal(signal.SIGINT, lambda signum, frame: noted.append(signum))
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
        try:
            from common import envswitch
            from common.errors import UsageError

            try:  # before the imports: node.stepcore reads TESTBED_STEPCORE as it is imported
                envswitch.check()
            except UsageError as e:
                sys.stderr.write(f"testbed: error: {e}\n")
                return e.exit_status
            from testbed.cli import main as cli_main
        finally:
            if noting:
                signal.signal(signal.SIGINT, signal.default_int_handler)
        if noted:
            raise KeyboardInterrupt
        return cli_main()
    except KeyboardInterrupt:
        sys.stderr.write("testbed: interrupted\n")
        return EXIT_INTERRUPTED
