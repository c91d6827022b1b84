"""`make bench`: every benchmark that exists, each writing results/bench/NAME.json.

A benchmark is a module testbed.bench.NAME with a run() function; one that fails is reported
and the others still run.
"""

import importlib
import importlib.util
import os
import sys
import traceback

BENCHMARKS = ("medium", "aodv", "node")


def main() -> int:
    if os.geteuid() != 0:
        print("bench: needs root (network namespaces): run `sudo make bench`", file=sys.stderr)
        return 2
    failed = []
    for name in BENCHMARKS:
        module = f"testbed.bench.{name}"
        if importlib.util.find_spec(module) is None:
            print(f"bench: {name}: not built yet, skipped")
            continue
        try:
            importlib.import_module(module).run()
        except Exception:
            traceback.print_exc()
            failed.append(name)
    if failed:
        print(f"bench: failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
