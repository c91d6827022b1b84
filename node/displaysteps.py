"""The steps at which the display acts, which are the only steps the world sends it a frame for.

The display (node.display) has no body and no deadline of its own: a frame tells it the step,
and it acts on a few of them. It floods a beacon every `map_period` steps, keeps a video
frame every `video_every` steps and saves a snapshot at each chosen step. Waking its Python
process for every other step too cost a lone robot's run 0.08 ms a step (a quarter of the
display's CPU while stepping; docs/measurements.md), so the world (testbed.run.steploop)
sends the display only the frames of the steps `wanted` names, plus the last step's (the
final snapshot is named after it). Both sides read this one description, so they cannot
disagree on which steps those are. The display's events carry the step of its last frame.
"""

from __future__ import annotations

from dataclasses import dataclass

VIDEO_EVERY = 10  # steps between the display's video frames (node.launch's default)


@dataclass(frozen=True)
class DisplaySteps:
    """Which steps the display acts on (periods of at least one step)."""

    map_period: int
    video_every: int = VIDEO_EVERY
    snapshots: frozenset[int] = frozenset()

    def __post_init__(self) -> None:
        object.__setattr__(self, "map_period", max(1, self.map_period))
        object.__setattr__(self, "video_every", max(1, self.video_every))

    def beacon(self, step: int) -> bool:
        return step % self.map_period == 0

    def video(self, step: int) -> bool:
        return step % self.video_every == 0

    def snapshot(self, step: int) -> bool:
        return step in self.snapshots

    def wanted(self, step: int) -> bool:
        """True when the display acts on `step`: the world sends it that step's frame."""
        return self.beacon(step) or self.video(step) or self.snapshot(step)
