"""What every layer shares and none owns: the two kinds of error and their exit statuses
(errors), JSON files written whole or not at all (jsonfile), and argparse types for numbers
with bounds (argtypes). It imports nothing of the project, so the robot program (node/), the
routing daemon (aodv/), the kernel layer (topology/) and the harness (testbed/) may all use it.
"""
