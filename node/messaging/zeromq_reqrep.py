"""ZeroMQ request/reply, the deliberately naive variant ("zeromq-reqrep"): every send waits
for the teammate's reply, without a bound (`ZeroMQReqRepMessenger`).

The paper worried that a robot using ZeroMQ blocks when a teammate is gone. Taken literally
that is this messenger: one REQ socket per teammate, and each send is a request that returns
only when the teammate's REP socket has answered it. No send or receive timeout, no
ZMQ_IMMEDIATE (a request to a teammate that is not connected is queued and waits for it),
no retry: a teammate that died after taking the request, or that never comes back, blocks
the sending thread (and anything else that sends to that teammate) until the run ends.
That is the point of it: the blocking is measured, not assumed (`stats`: `blocked_s` and
`blocked_max_s` include a send still waiting, `sending` says how many are). Use zeromq (PUSH/PULL
with bounded waits) for what ZeroMQ's documentation recommends.

What is set: ZMQ_LINGER 0 (closing drops what is queued) and the reconnect intervals from
`reconnect_ms`, as for every ZeroMQ socket here; closing the messenger ends a send that is
still waiting (False). The REP socket answers each request with an empty reply as soon as
receive() takes it. The wire is ZMTP 3 over TCP on the robot's goal port; each request
carries an empty delimiter frame before the message, each reply the delimiter and an empty
frame.
"""

from __future__ import annotations

import zmq

from node.messaging.zmqsockets import ZmqSockets

REPLY = b""


class ZeroMQReqRepMessenger(ZmqSockets):
    name = "zeromq-reqrep"
    LISTEN_TYPE = zmq.REP
    PEER_TYPE = zmq.REQ

    def _peer_options(self, sock: zmq.Socket) -> None:
        pass  # naive on purpose: ZeroMQ's defaults (no timeouts, queue before connecting)

    def _hand_over(self, sock: zmq.Socket, data: bytes) -> bool:
        sock.send(data)
        sock.recv()  # the teammate's reply: waits as long as it takes
        return True

    def _answer(self, sock: zmq.Socket) -> None:
        try:
            sock.send(REPLY, zmq.NOBLOCK)
        except zmq.Again:  # the requester is gone: its reply has nowhere to go
            pass
