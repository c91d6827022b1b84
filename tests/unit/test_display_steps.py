"""The steps the display acts on, which both the display and the world read (node.displaysteps):
the world sends the display a frame at exactly these steps (and the last one)."""

from types import SimpleNamespace

from hypothesis import given
from hypothesis import strategies as st

from node.displaysteps import VIDEO_EVERY, DisplaySteps
from node.launch import NodeArgs
from testbed.files.runconfig import RunConfig
from testbed.run.prepare import PreparedRun


def test_beacons_video_frames_and_snapshots_are_the_steps_wanted():
    s = DisplaySteps(map_period=7, video_every=10, snapshots=frozenset({13, 250}))
    wanted = [k for k in range(0, 60) if s.wanted(k)]
    assert wanted == [0, 7, 10, 13, 14, 20, 21, 28, 30, 35, 40, 42, 49, 50, 56]
    assert s.beacon(21) and not s.video(21) and s.video(30) and s.snapshot(13)


@given(st.integers(-3, 40), st.integers(-3, 40), st.frozensets(st.integers(0, 500)),
       st.integers(0, 500))  # fmt: skip
def test_a_step_is_wanted_exactly_when_the_display_acts_on_it(period, every, snaps, step):
    s = DisplaySteps(period, every, snaps)
    acts = step % max(1, period) == 0 or step % max(1, every) == 0 or step in snaps
    assert s.wanted(step) == acts


def test_the_display_and_the_world_read_the_same_periods():
    """The display is started with NodeArgs' video_every and the run's map_period and
    snapshots: the world's description of its steps is made of the same."""
    assert NodeArgs.__dataclass_fields__["video_every"].default == VIDEO_EVERY
    cfg = RunConfig(robots=1, comm_range=20.0, map_period=4, snapshots=(9,))
    prep = SimpleNamespace(cfg=cfg, snapshots=(9,))  # what the property reads of a PreparedRun
    got = PreparedRun.display_steps.fget(prep)  # type: ignore[attr-defined]
    assert got == DisplaySteps(4, VIDEO_EVERY, frozenset({9}))
