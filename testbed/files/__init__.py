"""The testbed's own files, the ground floor of testbed/: the run option table and the one
type of every file a run or a sweep writes and others read again.

The option table (runconfig.py, in options.py's terms; failures.py and isolation.py, the
meaning of two of its options), result.json (resultfile.py: its config, resultconfig.py; its
checked values, resultvalues.py; its ranges, resultcheck.py), config.json (configfile.py),
the CSVs (csvfiles.py), robots/rK.json (robotfile.py), sweep.json (sweepstate.py), a Slurm
sweep's jobs file (slurmjobs.py), medium.json (mediumfile.py), a captured network's
network.json (networkfile.py), the capture metrics' routing.json and metrics.json
(routingfile.py), and where the rest of a run
directory's files are (layout.py: events.jsonl, clock.csv, robots/, display/, pcaps/).

These modules hold data and its checks, nothing that runs a testbed: they import common/,
each other and named constants of node/ and topology/ (tests/unit/test_layers.py lists
which), never a web server, OpenCV or a check that starts a process. What only this machine
can answer about a run (is the C++ robot built, can the view listen there) is
testbed.run.arguments's. Reading one result.json loads a handful of modules
(tests/unit/test_import_budget.py).
"""
