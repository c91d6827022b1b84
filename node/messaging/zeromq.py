"""ZeroMQ (pyzmq) used as its documentation recommends for one-way messages with bounded
waits: a PULL socket to hear, one PUSH socket per teammate (`ZeroMQMessenger`).

Why PUSH/PULL and not DEALER/ROUTER: a goal or a re-plan request is one message to one
teammate, never answered, and each PUSH socket has one peer, so there is nothing to route:
ROUTER's identity frames would only add bytes. It is also the pattern of the default
middleware (nanomsg's PUSH/PULL), so the two differ in their library, not in their use.

Each PUSH socket is set up for a robot that must never wait long:

- ZMQ_IMMEDIATE 1: a message is queued only to a completed connection, never for a teammate
  that is not connected (ZeroMQ would otherwise keep it, and deliver it late, or never);
- ZMQ_SNDTIMEO = send_timeout_ms: a send with no room (not connected, or the queue full)
  gives up after that long (False);
- ZMQ_SNDHWM 8: at most 8 messages queued per teammate, as nanomsg's send buffer;
- ZMQ_LINGER 0: closing drops what is still queued, at once;
- ZMQ_RECONNECT_IVL / ZMQ_RECONNECT_IVL_MAX = reconnect_ms: the first wait before
  reconnecting to a teammate, and the ceiling it doubles up to.

Heartbeats (ZMQ_HEARTBEAT_IVL) and TCP keepalives stay off, as with nanomsg; the connect
timeout is the kernel's. Every interval is an argument in wall ms, from node.timing, already
divided by the run's time scale. The wire is ZMTP 3 over TCP on the robot's goal port: a
64-byte greeting each way and a READY command when a connection opens, then each message
as one frame (a 2-byte header for messages under 256 bytes).
"""

from __future__ import annotations

import zmq

from node.messaging import SEND_QUEUE
from node.messaging.zmqsockets import ZmqSockets

SEND_HWM = SEND_QUEUE  # messages queued per teammate (nanomsg's send_buffer_size)


class ZeroMQMessenger(ZmqSockets):
    name = "zeromq"
    LISTEN_TYPE = zmq.PULL
    PEER_TYPE = zmq.PUSH

    def _peer_options(self, sock: zmq.Socket) -> None:
        sock.setsockopt(zmq.IMMEDIATE, 1)
        sock.setsockopt(zmq.SNDTIMEO, self.send_timeout_ms)
        sock.setsockopt(zmq.SNDHWM, SEND_HWM)

    def _hand_over(self, sock: zmq.Socket, data: bytes) -> bool:
        try:
            sock.send(data)
        except zmq.Again:  # no connected teammate, or its queue full, for send_timeout_ms
            return False
        return True
