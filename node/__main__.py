"""`python -m node --robot r3 --robots 5 --body PATH ...`: one robot (or the display) process.

Started by `testbed run` inside the robot's namespace. Bad arguments: one line, exit 2.
"""

from __future__ import annotations

import argparse
import logging
import re
import signal
import sys

from node.events import EventLog
from node.flood import MODES, Flooder
from testbed.world import body
from topology.argtypes import number

STEP_S = 0.1  # emulated seconds per step


def robot_number(text: str) -> int:
    m = re.fullmatch(r"r?(\d{1,3})", text)
    if not m or int(m[1]) < 1:
        raise argparse.ArgumentTypeError(f"{text!r} is not a robot name like r3")
    return int(m[1])


def shape(text: str) -> tuple[int, int]:
    m = re.fullmatch(r"(\d{1,5})x(\d{1,5})", text)
    if not m or int(m[1]) < 1 or int(m[2]) < 1:
        raise argparse.ArgumentTypeError(f"{text!r} is not ROWSxCOLS")
    return int(m[1]), int(m[2])


def steps(text: str) -> set[int]:
    try:
        return {int(s) for s in text.split(",") if s.strip()}
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a list of steps") from None


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, exit 2
        sys.stderr.write(f"node: {message}\n")
        sys.exit(2)


def parser() -> argparse.ArgumentParser:
    p = _Parser(prog="python -m node", description=__doc__)
    p.add_argument("--robot", type=robot_number, required=True)
    p.add_argument(
        "--robots",
        type=number(int, "--robots", above=0),
        required=True,
        help="team size (exploring)",
    )
    p.add_argument("--role", choices=("robot", "display"), default="robot")
    p.add_argument("--body", required=True, help="Unix socket of the world's body link")
    p.add_argument("--events", help="JSON-lines event log to append to")
    p.add_argument("--map-size", type=shape, default=(400, 400), help="ROWSxCOLS cells")
    p.add_argument("--cell", type=number(float, "--cell", above=0), default=0.05)
    p.add_argument("--laser-range", type=number(float, "--laser-range", above=0), default=2.0)
    p.add_argument("--laser-rays", type=number(int, "--laser-rays", above=0), default=360)
    p.add_argument(
        "--speed", type=number(float, "--speed", above=0), default=0.1, help="metres per step"
    )
    p.add_argument("--radius", type=number(float, "--radius", above=0), default=0.15)
    p.add_argument("--plan-period", type=number(int, "--plan-period", above=0), default=20)
    p.add_argument("--map-period", type=number(int, "--map-period", above=0), default=10)
    p.add_argument("--time-scale", type=number(float, "--time-scale", above=0), default=1.0)
    p.add_argument("--timer-phase", type=int, default=0, help="steps added to the first timer")
    p.add_argument("--iface", default="wlan0", help="'' to not bind floods to a device")
    p.add_argument("--flood-port", type=number(int, "--flood-port", above=0), default=5100)
    p.add_argument(
        "--flood",
        choices=MODES,
        default="pruned",
        help="map flooding: self-pruning (default) or blind (every robot relays)",
    )
    p.add_argument("--goal-port", type=number(int, "--goal-port", above=0), default=5101)
    p.add_argument("--bind", help="address for the goal socket (default: the robot's)")
    p.add_argument("--out-dir", help="display: where snapshots and the video go")
    p.add_argument("--snapshots", type=steps, default=set(), help="display: steps, e.g. 100,500")
    p.add_argument("--video-every", type=number(int, "--video-every", above=0), default=10)
    return p


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
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
    if args.role == "display" and not args.out_dir:
        sys.stderr.write("node: the display needs --out-dir\n")
        return 2
    events = EventLog(args.events)
    stop = {"robot": None}

    def on_term(signum, frame):
        r = stop["robot"]
        if r is not None:
            r.stopping.set()

    signal.signal(signal.SIGTERM, on_term)
    try:
        role = body.ROLE_DISPLAY if args.role == "display" else body.ROLE_ROBOT
        link = body.BodyClient(args.body, me, role)
        # A neighbour is forgotten 1.5 map periods after it was last heard (node.flood).
        hold = 1.5 * args.map_period * STEP_S / args.time_scale
        flooder = Flooder(me, args.flood_port, args.iface or None, mode=args.flood, hold=hold)
    except OSError as e:
        sys.stderr.write(f"node: r{me}: cannot start: {e}\n")
        return 1
    if args.role == "display":
        from node.display import Display

        d = Display(
            me, args.map_size, args.cell, link, flooder, events, args.out_dir,
            args.snapshots, args.video_every, map_period=args.map_period,
        )  # fmt: skip
        stop["robot"] = d
        log.info("display up")
        d.run()
    else:
        from node.goalnet import GoalNet
        from node.robot import Robot, RobotConfig
        from topology.names import robot_addr

        cfg = RobotConfig(
            robot=me, robots=args.robots, shape=args.map_size, cell=args.cell,
            laser_range=args.laser_range, laser_rays=args.laser_rays, speed=args.speed,
            radius=args.radius, plan_period=args.plan_period, map_period=args.map_period,
            time_scale=args.time_scale, phase=max(0, args.timer_phase),
        )  # fmt: skip
        goals = GoalNet(
            me, args.bind or robot_addr(me), args.goal_port, robot_addr,
            send_timeout_ms=max(2, round(50 / args.time_scale)),
        )  # fmt: skip
        r = Robot(cfg, link, flooder, goals, events)
        stop["robot"] = r
        log.info("robot up: team of %d, laser %.1f m", args.robots, args.laser_range)
        try:
            r.run()
        finally:
            goals.close()
    flooder.close()
    link.close()
    events.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
