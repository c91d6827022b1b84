"""The two kinds of error the testbed distinguishes; the CLI (testbed.cli) prints either as
one line and exits with its `exit_status`.

`UsageError` is bad input from the user (CLI arguments, a config or sweep file, not root, a
missing tool or kernel feature): exit status 2. `TestbedError` is a failure while doing the
work (a kernel command that failed, a robot that crashed): exit status 1. Anything else is a
bug and keeps its traceback. They live here, in the lowest layer that raises them, so that
topology/ needs nothing from testbed/.
"""

EXIT_USAGE = 2
EXIT_FAILURE = 1


class TestbedError(Exception):
    """A failure while running the testbed; its message is one line for the user."""

    exit_status = EXIT_FAILURE
    __test__ = False  # not a pytest test class despite the name


class UsageError(TestbedError):
    """Bad input from the user: arguments, files, privileges, missing tools."""

    exit_status = EXIT_USAGE
