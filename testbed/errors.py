"""The testbed's two kinds of error, defined in topology.errors (the lowest layer that raises
them) and re-exported here for the code of runs, sweeps and reports: `UsageError` (bad input,
exit 2) and `TestbedError` (a failure while working, exit 1)."""

from topology.errors import EXIT_FAILURE, EXIT_USAGE, TestbedError, UsageError

__all__ = ["EXIT_FAILURE", "EXIT_USAGE", "TestbedError", "UsageError"]
