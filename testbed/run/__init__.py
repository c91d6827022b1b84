"""One exploration run, `testbed run`: its options (config, options), its stages (prepare,
then execute's Run and steploop's StepLoop), what the step loop keeps (stepclock, stalls,
record, files, progress), what a run does to its robots on purpose (failures, isolation)
and what it writes at the end (results, with the fidelity verdict). execute.py's docstring
tells how they join.
"""
