"""Which AODV daemon a run (or `testbed net up`) starts: the compiled daemon (build/tb-aodv,
native/aodv/daemon) or the Python daemon (`python -m aodv`, the reference), and why
(result.json's `aodv_daemon` and `aodv_daemon_reason`).

Both take the same command line and write the same statistics file (topology.routing), so the
choice changes what runs, not what the run records. `--aodv-daemon auto` (the default) takes
the compiled daemon wherever `make setup` built it; elsewhere the Python daemon runs and the
reason says why, with make setup's line (build/tb-aodv.unbuilt) where it could not build it.
`--aodv-daemon cpp` insists (a run without the program is refused before it starts);
`--aodv-daemon python` asks for the reference. With a routing other than aodv no AODV daemon
runs: the option is not used, nothing is refused, and the run says so.
"""

from __future__ import annotations

from testbed.files.runconfig import AODV_DAEMON_CHOICES as CHOICES  # auto, cpp, python
from topology import routing
from topology.spec import AODV_DAEMONS

AODV = "aodv"


def _not_built(unbuilt: str | None) -> str:
    return unbuilt or f"{routing.TB_AODV.name} not built (make setup builds it where g++ is)"


def choose(
    asked: str, routing_name: str, built: bool | None = None, unbuilt: str | None = None
) -> tuple[str | None, str]:
    """(the AODV daemon, "cpp" or "python", or None where the routing runs none; the reason)
    for `--aodv-daemon asked` with `--routing routing_name`. `built` and `unbuilt` (make
    setup's line) are asked of this machine when not given. ValueError for an unknown choice,
    and for `cpp` where the compiled daemon is not built."""
    if asked not in CHOICES:
        raise ValueError(f"--aodv-daemon {asked!r}: one of {', '.join(CHOICES)}")
    if routing_name != AODV:
        return None, f"routing {routing_name} runs no AODV daemon"
    if asked == "python":
        return "python", "python: asked for"
    if built is None:
        built = routing.aodv_built()
        unbuilt = routing.aodv_unbuilt_reason()
    if asked == "cpp":
        if not built:
            raise ValueError(f"--aodv-daemon cpp: the compiled AODV daemon is not there: "
                             f"{_not_built(unbuilt)}")  # fmt: skip
        return "cpp", "cpp: asked for"
    if not built:
        return "python", f"auto: the compiled daemon is not built: {_not_built(unbuilt)}"
    return "cpp", f"auto: {routing.TB_AODV.name} built"


def spec_daemon(asked: str, routing_name: str) -> str:
    """The NetworkSpec's `aodv_daemon` for these options: the one `choose` takes, or the
    spec's default where the routing runs none. ValueError as `choose`."""
    daemon, _ = choose(asked, routing_name)
    return daemon or AODV_DAEMONS[0]
