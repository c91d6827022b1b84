"""A run directory's layout: where each of its files is, named in one place.

docs/run-results.md says what each file holds. The files with a type of their own keep
their name beside the type (result.json: testbed.files.resultfile; config.json:
testbed.files.configfile; the CSVs: testbed.files.csvfiles; robots/rK.json:
testbed.files.robotfile); the rest are here, with the paths built from them:

    DIR/events.jsonl              what the run did to its robots on purpose (run_events)
    DIR/clock.csv                 when each step's frames went out (clock_path)
    DIR/medium.json               the ns3-wifi channel's counters (medium_path)
    DIR/robots/rK.events.jsonl    robot K's event log (robot_events; node.events' suffix)
    DIR/display/                  the display's snapshots and video, events.jsonl
                                  (display_events) and the final map, map.npy (map_path)
    DIR/pcaps/                    the captures, and daemons/ their daemons' files
"""

from __future__ import annotations

import os

ROBOTS_DIR = "robots"
DISPLAY_DIR = "display"
PCAPS_DIR = "pcaps"
DAEMONS_DIR = "daemons"  # under pcaps/
EVENTS_NAME = "events.jsonl"  # the run's, and the display's in display/
CLOCK_NAME = "clock.csv"
MEDIUM_NAME = "medium.json"
MAP_NAME = "map.npy"  # in display/

PathLike = str | os.PathLike[str]


def run_events(out: PathLike) -> str:
    return os.path.join(out, EVENTS_NAME)


def clock_path(out: PathLike) -> str:
    return os.path.join(out, CLOCK_NAME)


def medium_path(out: PathLike) -> str:
    return os.path.join(out, MEDIUM_NAME)


def robots_dir(out: PathLike) -> str:
    return os.path.join(out, ROBOTS_DIR)


def robot_events(out: PathLike, k: int) -> str:
    """Robot k's event log (node.events writes it; the C++ robot the same)."""
    from node.events import EVENTS_SUFFIX  # here: readers of the other paths need no node

    return os.path.join(out, ROBOTS_DIR, f"r{k}{EVENTS_SUFFIX}")


def display_dir(out: PathLike) -> str:
    return os.path.join(out, DISPLAY_DIR)


def display_events(out: PathLike) -> str:
    return os.path.join(out, DISPLAY_DIR, EVENTS_NAME)


def map_path(out: PathLike) -> str:
    """The display's final map (what the team knew at the end)."""
    return os.path.join(out, DISPLAY_DIR, MAP_NAME)


def pcaps_dir(out: PathLike) -> str:
    return os.path.join(out, PCAPS_DIR)


def daemons_dir(out: PathLike) -> str:
    """The capture's daemons' files (their logs, tcpdump's)."""
    return os.path.join(out, PCAPS_DIR, DAEMONS_DIR)
