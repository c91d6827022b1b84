"""What a run's start brought up (`Started`: its network, the body server, the open files,
the display's process and the live view), which testbed.run.execute makes and
testbed.run.steploop steps; a module of its own so that the step loop needs nothing of
execute.py."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from testbed.run.files import RunFiles
    from testbed.view.live import LiveServer
    from testbed.world.bodylink import BodyServer
    from topology.kernel.forkserver import Forked
    from topology.network import Network


@dataclass(frozen=True)
class Started:
    """What `Run.start()` brought up; the ExitStack it was given takes it down."""

    net: Network
    server: BodyServer
    files: RunFiles
    display_proc: Forked
    live: LiveServer | None  # --view

    @property
    def network_timers(self) -> dict | None:
        """The robot namespaces' network timers (topology.kernel.nettimers), as result.json has
        them."""
        timers = self.net.timers
        return None if timers is None else timers.to_dict()
