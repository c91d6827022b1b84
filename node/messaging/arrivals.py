"""What arrived from teammates, judged from the messages themselves (`Arrivals`): duplicates,
and messages that came late.

A goal or re-plan request carries its sender, the sender's step when it was sent, and the
sender's message number (node.wire). Every robot counts the same steps (the world's frames),
so the receiver's step minus the message's is how long the message took, in steps. A message
is *late* when it took more than LATE_STEPS: sent in one step, it should be there by the
next one (a step is 100 ms of emulated time; the send timeout is half of that). A
*duplicate* is a message number from a sender that was seen before: the middleware
delivered one message twice. Messages without a number (older senders) are not judged
for duplicates.
"""

from __future__ import annotations

LATE_STEPS = 1  # a message that took more steps than this arrived late


class Arrivals:
    def __init__(self) -> None:
        self.seen: dict[int, set[int]] = {}  # sender -> message numbers received
        self.messages = 0
        self.duplicates = 0
        self.late = 0
        self.delay_steps_max = 0

    def note(self, sender: int, n: int | None, sent_step: int, step: int) -> None:
        """A message of `sender`, number `n`, sent at its step `sent_step`, arrived at `step`."""
        self.messages += 1
        delay = step - sent_step
        self.delay_steps_max = max(self.delay_steps_max, delay)
        if delay > LATE_STEPS:
            self.late += 1
        if n is None:
            return
        seen = self.seen.setdefault(sender, set())
        if n in seen:
            self.duplicates += 1
        seen.add(n)

    def as_dict(self) -> dict:
        return {
            "messages": self.messages,
            "duplicates": self.duplicates,
            "late": self.late,
            "delay_steps_max": self.delay_steps_max,
        }
