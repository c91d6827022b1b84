"""Maps over publish/subscribe (`--maps pubsub`, node.messaging.maps) in a real team run.

A team of three explores a walled 4 x 4 m room, once with maps flooded (the reference) and
once with maps published on the middleware's topics, for Zenoh and for DDS (a middleware
whose Python package is missing is skipped). With pubsub: the run finishes; every robot
received maps from both teammates over the middleware and none by flood (no flood was
relayed); the display (robot 4) subscribed too, so it received every robot's maps and its
map covers the room as the flooded run's does; rK.json and result.json's `maps` carry the
same counters, and no publish waited longer than the send timeout.
"""

import json
import os
import subprocess
import uuid

import cv2
import numpy as np
import pytest

from node import messaging
from testbed import PROJECT_ROOT
from topology.network import destroy

ROBOTS = 3
TIME_SCALE = 5
SEND_TIMEOUT_S = 0.050 / TIME_SCALE  # node.timing's goal send timeout, scaled
SLACK_S = 0.5  # a loaded two-core machine's scheduling


def _room(path: str) -> None:
    """A walled 4 x 4 m room (80 x 80 pixels of 5 cm)."""
    img = np.full((80, 80), 255, dtype=np.uint8)
    img[:2, :] = img[-2:, :] = img[:, :2] = img[:, -2:] = 0
    cv2.imwrite(path, img)


def _run(tmp: str, middleware: str, maps: str) -> str:
    """A team run of the room; its directory."""
    name = "mwm" + uuid.uuid4().hex[:5]
    room, out = os.path.join(tmp, "room.png"), os.path.join(tmp, f"{middleware}-{maps}")
    if not os.path.exists(room):
        _room(room)
    argv = [
        os.path.join(PROJECT_ROOT, ".venv", "bin", "testbed"), "run", "--robots", str(ROBOTS),
        "--comm-range", "20", "--laser-range", "1.5", "--map", room,
        "--time-scale", str(TIME_SCALE), "--max-steps", "1500", "--middleware", middleware,
        "--maps", maps, "--name", name, "--out", out, "--quiet",
    ]  # fmt: skip
    try:
        r = subprocess.run(argv, capture_output=True, text=True, timeout=300)
    finally:
        destroy(name)
    assert r.returncode == 0, r.stderr[-2000:]
    return out


def _json(*parts: str) -> dict:
    with open(os.path.join(*parts)) as f:
        return json.load(f)


@pytest.fixture(scope="module")
def flooded(tmp_path_factory) -> dict:
    """The reference: the same team with its maps flooded (over nanomsg's goals)."""
    out = _run(str(tmp_path_factory.mktemp("flood")), "nanomsg", "flood")
    return _json(out, "result.json")


@pytest.mark.parametrize("middleware", ["zenoh", "dds"])
def test_a_team_shares_its_maps_over_pubsub(tmp_path, middleware, flooded):
    why = messaging.unavailable(middleware)
    if why:
        pytest.skip(why)
    out = _run(str(tmp_path), middleware, "pubsub")
    result = _json(out, "result.json")
    assert result["status"] == "complete", result["status_detail"]
    assert result["config"]["extra"]["maps"] == "pubsub"
    maps = result["maps"]
    assert (maps["transport"], maps["middleware"]) == ("pubsub", middleware)
    assert maps["team"]["robots"] == ROBOTS
    team = [f"r{k}" for k in range(1, ROBOTS + 1)]
    for k in range(1, ROBOTS + 1):
        me = f"r{k}"
        detail = _json(out, "robots", f"{me}.json")
        counters = detail["maps"]
        assert counters == maps["robots"][me]
        assert counters["transport"] == "pubsub"
        mates = [j for j in team if j != me]
        assert sorted(counters["received_from"]) == mates  # from both teammates
        assert all(counters["received_from"][j] >= 1 for j in mates)
        messages = detail["messages"]
        # What arrived went to the merge, but for the last map of a teammate or so: taken
        # in as the run ended, after message processing stopped.
        merged = messages["received"]["map"]
        assert counters["received"] - len(mates) <= merged <= counters["received"]
        assert counters["published"] + counters["failed"] == messages["sent"]["map"]
        assert counters["published"] >= 1 and counters["bytes_published"] > 0
        assert counters["blocked_max_s"] <= SEND_TIMEOUT_S + SLACK_S
        assert detail["flood"].get("relayed", 0) == 0  # nobody flooded, nobody relayed
        with open(os.path.join(out, "robots", f"{me}.events.jsonl")) as f:
            events = [json.loads(line) for line in f]
        frm = {e["frm"] for e in events if e["e"] == "recv" and e["kind"] == "map"}
        assert frm == {int(j[1:]) for j in mates}
        assert any(e["e"] == "recv" and e["kind"] == "beacon" for e in events)  # the display's
    display = maps["display"]
    assert sorted(display["received_from"]) == team  # the display subscribed
    assert all(display["received_from"][j] >= 1 for j in team)
    coverage = result["display"]["coverage_final"]
    assert coverage >= flooded["display"]["coverage_final"] - 0.05, (coverage, flooded)
    assert flooded["maps"]["transport"] == "flood" and flooded["maps"]["middleware"] is None
