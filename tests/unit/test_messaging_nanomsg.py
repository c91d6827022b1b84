"""The nanomsg messenger's nng sockets (node.messaging.nanomsg) keep the intervals node.timing
gives them."""

from node.messaging.nanomsg import NanomsgMessenger
from node.timing import RobotTimings


def _messenger(timing: RobotTimings) -> NanomsgMessenger:
    # Port 0: the listener takes a free port; teammates are dialled without blocking.
    return NanomsgMessenger(
        1, "127.0.0.1", 0, lambda k: "127.0.0.1",
        send_timeout_ms=timing.goal_send_timeout_ms,
        reconnect_ms=(timing.goal_reconnect_min_ms, timing.goal_reconnect_max_ms),
    )  # fmt: skip


def test_a_teammates_socket_redials_and_gives_up_on_the_dilated_clock():
    for scale, want in ((1.0, (50, 500, 50)), (10.0, (5, 50, 5)), (1000.0, (1, 1, 2))):
        g = _messenger(RobotTimings(time_scale=scale))
        try:
            s = g._socket(2)
            got = (s.reconnect_time_min, s.reconnect_time_max, s.send_timeout)
            assert got == want, scale
            # The dialer nng made for the teammate took the socket's backoff.
            assert s.dialers[0].reconnect_time_min == want[0]
        finally:
            g.close()


def test_the_backoffs_ceiling_is_never_below_its_start():
    g = NanomsgMessenger(1, "127.0.0.1", 0, lambda k: "127.0.0.1", reconnect_ms=(40, 10))
    try:
        assert g.reconnect_ms == (40, 40)
    finally:
        g.close()
