"""Networks by hand, `testbed net ...` and `testbed clean`: the subcommands (commands) and what
moves the robots of a hand-made network from outside, a trace player or a live feed (movers).
"""
