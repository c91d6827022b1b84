"""The goal messenger's first name: `GoalNet` is node.messaging.nanomsg's NanomsgMessenger.

The robots' unicast messages went over nanomsg only, through `node.goalnet.GoalNet`, before
the middleware became a run option (node.messaging). Code and tests written against that
name keep working; new code opens its messenger with node.messaging.open_messenger.
"""

from node.messaging.nanomsg import NanomsgMessenger as GoalNet

__all__ = ["GoalNet"]
