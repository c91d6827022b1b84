"""`make bench`: every benchmark that exists, each writing results/bench/NAME.json.
`python -m testbed.bench NAME ...` runs only those named.

A benchmark is a module testbed.bench.NAME with a run() function; one that fails is reported
and the others still run.
"""

import importlib
import importlib.util
import os
import sys
import traceback

BENCHMARKS = (
    "medium",
    "aodv",
    "aodv_profiles",
    "oracle",
    "los",
    "view",
    "node",
    "ns3wifi",
    "scale",
    "fidelity",
    "cost",
    "neighbours",
    "idle",
    "aodv_grid",
)


def main(argv: list[str]) -> int:
    if {"-h", "--help"} & set(argv):
        print(f"usage: python -m testbed.bench [NAME ...]   (NAME: {', '.join(BENCHMARKS)})")
        return 0
    unknown = [a for a in argv if a not in BENCHMARKS]
    if unknown:
        print(f"bench: no benchmark {unknown[0]!r} (there are: {', '.join(BENCHMARKS)})",
              file=sys.stderr)  # fmt: skip
        return 2
    if os.geteuid() != 0:
        print("bench: needs root (network namespaces): run `sudo make bench`", file=sys.stderr)
        return 2
    failed = []
    for name in argv or BENCHMARKS:
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
    sys.exit(main(sys.argv[1:]))
