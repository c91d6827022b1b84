"""`python -m testbed`: the `testbed` command, as the console script runs it."""

import sys

from testbed.console import main

if __name__ == "__main__":
    sys.exit(main())
