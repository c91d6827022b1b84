"""`python -m node --robot r3 --robots 5 --body PATH ...`: one robot (or the display) process.

Started by `testbed run` inside the robot's namespace. Bad arguments: one line, exit 2.

The maps travel by UDP flood (node.flood) or, with `--maps pubsub`, on the map topic of the
middleware's session (node.messaging.maps): then every robot opens its messenger with the
display among its peers, and the display opens one too, for its map topic alone.
"""

from __future__ import annotations

import logging
import signal
import sys
from typing import TYPE_CHECKING

from common import envswitch
from common.errors import UsageError

# The environment switches are read while node's modules load (node.stepcore): a robot
# started by hand with a value they do not know gets one line, not a traceback.
try:
    envswitch.check()
except UsageError as e:
    sys.stderr.write(f"node: {e}\n")
    sys.exit(2)

from node import body  # noqa: E402
from node.events import EventLog
from node.flood import Flooder
from node.launch import NodeArgs
from node.messaging.maps import refusal as maps_refusal
from node.timing import RobotTimings

if TYPE_CHECKING:
    from node.display import Display
    from node.robot import Robot


def _open_messenger(args: NodeArgs, timing: RobotTimings, team: tuple[int, ...]):
    """The node's messenger (node.messaging), or MiddlewareUnavailable."""
    from node.messaging import open_messenger
    from topology.names import robot_addr

    me = args.robot
    return open_messenger(
        args.middleware, me=me, bind_addr=args.bind or robot_addr(me), port=args.goal_port,
        addr_of=robot_addr, team=team, send_timeout_ms=timing.goal_send_timeout_ms,
        reconnect_ms=(timing.goal_reconnect_min_ms, timing.goal_reconnect_max_ms),
    )  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    args = NodeArgs.parse(argv)
    me = args.robot
    # Motion control must answer each frame within a step (20 ms at time scale 5): switch
    # threads faster than Python's default 5 ms when a planner thread holds the interpreter.
    sys.setswitchinterval(0.0005)
    logging.basicConfig(
        level=logging.INFO,
        format=f"%(asctime)s r{me} %(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    log = logging.getLogger("node")
    timing = RobotTimings(time_scale=args.time_scale, map_period=args.map_period)
    if args.role == "display" and not args.out_dir:
        sys.stderr.write("node: the display needs --out-dir\n")
        return 2
    why = maps_refusal(args.maps, args.middleware)
    if why:
        sys.stderr.write(f"node: {why}\n")
        return 2
    pubsub = args.maps == "pubsub"
    # With pubsub the display (robot N+1) is a peer of every robot's session: it subscribes.
    team = tuple(range(1, args.robots + (2 if pubsub else 1)))
    try:
        events = EventLog(args.events)
    except OSError as e:  # a directory that is not there, /proc/self/mem, ...
        sys.stderr.write(f"node: r{me}: cannot open --events {args.events!r}: "
                         f"{e.strerror or e}\n")  # fmt: skip
        return 2
    stop: dict[str, Display | Robot | None] = {"robot": None}

    def on_term(signum, frame):
        r = stop["robot"]
        if r is not None:
            r.stopping.set()

    signal.signal(signal.SIGTERM, on_term)
    from node.messaging import MiddlewareUnavailable

    link = messenger = None
    try:
        role = body.ROLE_DISPLAY if args.role == "display" else body.ROLE_ROBOT
        link = body.BodyClient(args.body, me, role)
        if args.role == "robot" or pubsub:
            messenger = _open_messenger(args, timing, team)
        if pubsub:
            assert messenger is not None  # opened just above
            maps = messenger.map_topic()
        else:
            maps = Flooder(me, args.flood_port, args.iface or None, mode=args.flood,
                           hold=timing.neighbour_hold_s)  # fmt: skip
    except (OSError, MiddlewareUnavailable) as e:
        unavailable = isinstance(e, MiddlewareUnavailable)
        sys.stderr.write(
            f"node: r{me}: {e}\n" if unavailable else f"node: r{me}: cannot start: {e}\n"
        )
        for opened in (messenger, link, events):
            if opened is not None:
                opened.close()
        return 2 if unavailable else 1
    try:
        if args.role == "display":
            from node.display import Display

            assert args.out_dir is not None  # a display without one was refused above
            d = Display(
                me, args.map_size, args.cell, link, maps, events, args.out_dir,
                args.snapshots, args.video_every, map_period=args.map_period,
                time_scale=args.time_scale,
            )  # fmt: skip
            stop["robot"] = d
            log.info("display up (maps by %s)", args.maps)
            d.run()
        else:
            from node.robot import Robot, RobotConfig

            cfg = RobotConfig(
                robot=me, robots=args.robots, shape=args.map_size, cell=args.cell,
                laser_range=args.laser_range, laser_rays=args.laser_rays, speed=args.speed,
                radius=args.radius, plan_period=args.plan_period, map_period=args.map_period,
                timing=timing, phase=max(0, args.timer_phase), coordination=args.coordination,
            )  # fmt: skip
            assert messenger is not None  # opened above for a robot
            r = Robot(cfg, link, maps, messenger, events)
            stop["robot"] = r
            log.info("robot up: team of %d, laser %.1f m, maps by %s", args.robots,
                     args.laser_range, args.maps)  # fmt: skip
            r.run()
    finally:
        if messenger is not None:
            messenger.close()  # the map topic with it
        maps.close()
        link.close()
        events.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
