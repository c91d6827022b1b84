"""The `testbed` command: networks by hand (`net ...`, testbed.net), runs, sweeps, reports,
clean-up.

Every error the user can cause is one line on stderr and exit status 2 (common.errors); a
failure while working is one line and status 1. Tracebacks are for bugs only.
"""

import argparse
import contextlib
import faulthandler
import importlib
import importlib.util
import logging
import signal
import sys

from pyroute2.netlink.exceptions import NetlinkError

from common import envswitch
from common.errors import TestbedError, UsageError
from testbed.files.resultvalues import one_line
from testbed.net import commands

log = logging.getLogger("testbed")
# What --help says first: the docstring's first paragraph, whole.
DESCRIPTION = " ".join((__doc__ or "").split("\n\n")[0].split())


class Parser(argparse.ArgumentParser):
    """argparse, but a bad argument is a UsageError: one line, exit status 2."""

    def error(self, message: str):
        raise UsageError(f"{self.prog}: {message}")


# -- run, sweep, report: provided by their own modules -----------------------------------------

DELEGATED = {
    "run": ("testbed.run.execute", "run one exploration experiment"),
    "sweep": ("testbed.sweep.command", "run a sweep of experiments from a TOML file"),
    "report": ("testbed.analysis.report", "figures and a report from a sweep's results"),
    "view": ("testbed.view.server", "replay a finished run in the browser"),
    "compare": (
        "testbed.analysis.scalecompare",
        "two sweeps of the same points side by side "
        "(e.g. time scale 1 against a dilated one): within the noise or not",
    ),
    "decide": (
        "testbed.analysis.decidesweep",
        "plan (PLAN) or judge (JUDGE) the runs that decide the paper's claims after a sweep",
    ),
}


def build_parser(argv: list[str] | None = None) -> Parser:
    """The whole command line. Of the delegated commands only the one named in `argv` (all of
    them when argv names none) has its module imported: `testbed run` starts in a quarter of
    a second instead of paying for the report's matplotlib, and `net` or `clean` import none."""
    parser = Parser(prog="testbed", description=DESCRIPTION)
    parser.add_argument("-v", "--verbose", action="store_true", help="log what is done")
    sub = parser.add_subparsers(dest="cmd", required=True, parser_class=Parser)
    commands.add_parsers(sub)
    words = sys.argv[1:] if argv is None else argv
    command = next((w for w in words if not w.startswith("-")), None)
    # `net` and `clean` import none: matplotlib's first import may log a line of its own.
    named = set(words) & set(DELEGATED) or set(DELEGATED)
    chosen = set() if command in ("net", "clean") else named
    for cmd, (module, help_text) in DELEGATED.items():
        p = sub.add_parser(cmd, help=help_text)
        if cmd in chosen and importlib.util.find_spec(module) is not None:
            importlib.import_module(module).add_arguments(p)
    return parser


def dispatch(args) -> int:
    if args.cmd in ("net", "clean", "metrics"):  # metrics: testbed.net.movers' own
        return commands.run(args)
    return importlib.import_module(DELEGATED[args.cmd][0]).main(args)


# Set once SIGTERM arrived (a batch system cancelling the job, a time limit): whatever the
# run then ended with, it did not end on its own (testbed.sweep.slurm marks it interrupted).
terminated = False


def _stop_on_sigterm(signum, frame) -> None:
    global terminated
    terminated = True
    raise KeyboardInterrupt  # unwinds like Ctrl-C: every testbed is torn down on the way out


def main(argv: list[str] | None = None) -> int:
    signal.signal(signal.SIGTERM, _stop_on_sigterm)
    # SIGINT raises KeyboardInterrupt whatever was inherited. A command a shell script starts
    # with `&` inherits SIGINT ignored, and Python then installs no handler for it: a run
    # set up that way ignored the SIGINT a test or a script sent to end it, and stayed up.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    # SIGQUIT (Ctrl-\) prints every thread's stack and the command goes on: where a run
    # that seems stuck is waiting.
    # (Not where stderr is no file, as under a test's capture.)
    with contextlib.suppress(ValueError, OSError):
        faulthandler.register(signal.SIGQUIT, all_threads=True)
    try:
        args = build_parser(argv).parse_args(argv)
        envswitch.check()  # TESTBED_REALTIME=false is refused, not taken as the default
        logging.basicConfig(
            level=logging.INFO if args.verbose else logging.WARNING,
            format="%(asctime)s testbed %(name)s %(levelname)s: %(message)s",
        )
        return dispatch(args)
    except TestbedError as exc:  # one line, whatever a file's name or contents held
        print(f"testbed: error: {one_line(str(exc), 2000)}", file=sys.stderr)
        return exc.exit_status
    except KeyboardInterrupt:
        print("testbed: interrupted", file=sys.stderr)
        return 130
    except (OSError, NetlinkError) as exc:  # a kernel or file operation that failed
        print(f"testbed: error: {one_line(_os_error_text(exc), 2000)}", file=sys.stderr)
        return 1


def _os_error_text(exc: Exception) -> str:
    """`/etc/passwd/x: Not a directory` rather than `[Errno 20] Not a directory: '...'`;
    a NetlinkError (not an OSError) as it prints itself."""
    if isinstance(exc, OSError) and exc.strerror:
        return f"{exc.filename}: {exc.strerror}" if exc.filename else exc.strerror
    return str(exc)


if __name__ == "__main__":
    sys.exit(main())
