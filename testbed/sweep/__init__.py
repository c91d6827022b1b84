"""Many runs, `testbed sweep FILE --out DIR`: the sweep file and its grid (file), the run
directory contract (rundir), what is already done (plan), running them here (runner, with the
back-off of policy and the progress line) or on a Slurm cluster (slurm). command.py is the
command line that joins them.
"""
