"""`testbed run`'s command line, and the checks of a run's options that ask this machine.

The option table itself (`RunConfig`, `OPTIONS`) is testbed.files.runconfig: data that
readers of run and sweep files share, asking nothing of this machine. Here is what only a
run (or a sweep planning runs here) needs: the parser (`add_arguments`), the RunConfig of
parsed arguments (`config_from_args`, with the option rule and the checks below), whether
this machine's robot program and AODV daemon can carry a run (`refusal`: the C++ robot is
asked which middlewares it carries, testbed.run.robotchoice; the compiled daemon must be
built, testbed.run.daemonchoice), the live view's address (`--view`, testbed.view.server),
and the NetworkSpec fields `run` and `net up` share (`network_fields`, with the AODV daemon
chosen).
"""

from __future__ import annotations

import argparse

from common.errors import UsageError
from testbed.files import options as runoptions
from testbed.files import runconfig
from testbed.files.runconfig import NET_OPTIONS, OPTIONS, RunConfig
from testbed.run import daemonchoice, robotchoice

# The net options that are not a NetworkSpec field of the same name: its one Impairment.
_IMPAIRMENT_OPTIONS = ("loss_pct", "delay_ms")
GATE_TIMEOUT_S = 3600.0  # --start-timeout's default: how long a run waits at --start-when


def network_fields(values) -> dict:
    """The NetworkSpec fields that `net up` and `run` share, from a RunConfig or from `net
    up`'s parsed flags (both carry every net option under its name): what each caller adds
    is only its name, positions, map path and capture directory."""
    from topology.spec import Impairment

    fields = {o.name: getattr(values, o.name) for o in NET_OPTIONS}
    loss, delay = (fields.pop(name) for name in _IMPAIRMENT_OPTIONS)
    # auto becomes the daemon that runs (ValueError: cpp asked for where it is not built).
    fields["aodv_daemon"] = daemonchoice.spec_daemon(fields["aodv_daemon"], fields["routing"])
    return dict(fields, impairment=Impairment(loss_pct=loss, delay_ms=delay))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The `testbed run` options: the run options, then where the run goes and how it shows."""
    runoptions.add_to_parser(parser, OPTIONS)
    a = parser.add_argument
    a("--out", required=True, metavar="DIR", help="run directory to write (required)")
    a("--name", help="testbed name (default: random 'run' + 4 hex digits)")
    a("--quiet", action="store_true", help="no progress line (default off)")
    a("--replace", action="store_true",
      help="--out holds an earlier run: delete it first (default: refuse)")  # fmt: skip
    a("--steps-over", metavar="FILE",
      help="create FILE when the last step is done, before the teardown: a sweep starts its "
      "next run then (default: none)")  # fmt: skip
    a("--start-when", metavar="FILE",
      help="set up, then wait until FILE exists before the first step (the step clock starts "
      "then): a sweep pre-starts its next run so (default: none)")  # fmt: skip
    a("--start-timeout", metavar="S", type=_gate_timeout, default=GATE_TIMEOUT_S,
      help=f"with --start-when: end the run (status gate_timeout) when FILE is not there "
      f"after S seconds (default: {GATE_TIMEOUT_S:g})")  # fmt: skip


def _gate_timeout(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a positive number of seconds, not {text!r}")
    return value


def _view(text: str | None) -> str | None:
    if text is None:
        return None
    from testbed.view.server import parse_bind

    try:
        parse_bind(text)
    except ValueError as e:
        raise UsageError(str(e)) from None
    return text


def refusal(cfg: RunConfig, program: bool = True) -> tuple[str, str] | None:
    """The first check that `cfg` fails, as (the option it names, why in one line), or None:
    the option rule (testbed.files.runconfig.refusal), then with `program` whether the robot
    program asked for can carry the run (testbed.run.robotchoice: it asks the C++ robot built
    on this machine) and whether the AODV daemon asked for is built
    (testbed.run.daemonchoice)."""
    why = runconfig.refusal(cfg)
    if why or not program:
        return why
    try:
        robotchoice.choose(cfg.robot, cfg.middleware, cfg.maps)
    except ValueError as e:
        return "robot", str(e)
    try:
        daemonchoice.choose(cfg.aodv_daemon, cfg.routing)
    except ValueError as e:
        return "aodv_daemon", str(e)
    return None


def config_from_args(args: argparse.Namespace) -> RunConfig:
    """The RunConfig of parsed `testbed run` arguments, with the checks that join options
    and those of this machine (`refusal`)."""
    cfg = RunConfig(**runoptions.config_kwargs(args, OPTIONS))
    why = refusal(cfg)
    if why:
        raise UsageError(why[1])
    _view(cfg.view)
    return cfg
