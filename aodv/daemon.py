"""The AODV daemon of one robot: sockets, kernel routes, the TUN device and the clock.

Theory of operation
-------------------
One thread, one `selectors` loop over three file descriptors: the UDP socket on port 654
(control messages), the TUN device (data packets that found no kernel route) and a signal
wake-up socket. Everything protocol-related is delegated to `AodvCore`; this module only
turns IO into core events (with `time.monotonic()` as `now`) and core actions into IO:

    UDP 654 datagram  -> decode -> core.on_control(src, ttl)   Unicast/Broadcast -> sendto
    TUN packet        -> core.on_no_route(src, dst)            Install/DeleteRoute -> netlink
    nft "used" set    -> core.on_route_used(addr)               ReleasePackets -> raw socket
    deadline reached  -> core.on_timer()                        DropPackets -> ICMP via TUN

Control socket: bound to 0.0.0.0:654 and to the interface (SO_BINDTODEVICE), with
SO_BROADCAST; the IP TTL is set before each send and read on receipt (IP_RECVTTL = 12,
missing from Python 3.11's socket module). Broadcasts go to 255.255.255.255; unicasts use
MSG_DONTROUTE, as a control message always goes to a neighbour on the link. The socket
hears our own broadcasts: a socket filter drops them by source address (`_on_udp` checks
again).

Routes of the daemon carry protocol number RTPROT_AODV; they are flushed at start and at
exit. A start is a restart (RFC 6.13 reboot rule: DELETE_PERIOD without originating
control messages) when the counter file of a previous instance exists (`--state`,
aodv.persist: its sequence number and RREQ ID resume above what it used) or when such
routes of a dead predecessor are in the kernel.

Peer input is never trusted: a datagram that does not decode, or names addresses outside
the ad hoc network, is counted in stats["dropped"] and logged (rate-limited), never raised;
what the core bounds or refuses is counted in stats["protocol_dropped"]. An action that
fails (a message that will not encode, a send the kernel refuses) is counted and the
actions after it still run, so the kernel's routes always follow the core's table.
"""

from __future__ import annotations

import contextlib
import gc
import ipaddress
import logging
import selectors
import signal
import socket
import struct
import time

from aodv import packet as wire
from aodv.core import (
    AodvCore,
    Broadcast,
    DeleteRoute,
    DiscoveryDone,
    DropPackets,
    InstallRoute,
    ReleasePackets,
    Unicast,
)
from aodv.kernel import (
    KernelError,
    KernelRoutes,
    SetReader,
    Tun,
    UseMonitor,
    drop_own_datagrams,
)
from aodv.params import Params
from aodv.persist import CounterStore
from aodv.sim import warm_up
from aodv.stats import Stats
from common.sched import DEADLINE_PRIORITY, deadline_priority

log = logging.getLogger(__name__)

IP_RECVTTL = 12  # linux/in.h; not in Python 3.11's socket module
IP_TTL_CMSG = 2  # IP_TTL: the cmsg type of a received TTL
BROADCAST = "255.255.255.255"
STATS_PERIOD = 1.0  # wall seconds between rewrites of the stats file
_U32 = struct.Struct("!I")
ICMP_DEST_UNREACH = 3
_I32 = struct.Struct("i")  # a received TTL's cmsg data (native int)
HOSTS_REMEMBERED = 4096  # bound of the checked-address memory


def _checksum(data: bytes) -> int:
    if len(data) % 2:
        data += b"\0"
    s = sum(struct.unpack(f"!{len(data) // 2}H", data))
    s = (s >> 16) + (s & 0xFFFF)
    s += s >> 16
    return ~s & 0xFFFF


def icmp_host_unreachable(own: str, original: bytes) -> bytes:
    """An ICMP destination unreachable (type 3, code 1) about `original`, to its sender."""
    ihl = (original[0] & 0x0F) * 4
    quoted = original[: ihl + 8]
    icmp = struct.pack("!BBHI", 3, 1, 0, 0) + quoted
    icmp = icmp[:2] + struct.pack("!H", _checksum(icmp)) + icmp[4:]
    total = 20 + len(icmp)
    hdr = struct.pack(
        "!BBHHHBBH4s4s",
        0x45,
        0,
        total,
        0,
        0,
        64,
        socket.IPPROTO_ICMP,
        0,
        socket.inet_aton(own),
        original[12:16],
    )
    hdr = hdr[:10] + struct.pack("!H", _checksum(hdr)) + hdr[12:]
    return hdr + icmp


def quoted_datagram(icmp_packet: bytes, own: str) -> tuple[int, bytes] | None:
    """From an IPv4 packet carrying an ICMP destination unreachable, the AODV datagram it
    quotes if `own` sent it (UDP from port 654 to port 654): (its UDP length, the quoted
    part of its payload); None for anything else, short or malformed packets included."""
    try:
        outer = (icmp_packet[0] & 0x0F) * 4
        if icmp_packet[outer] != ICMP_DEST_UNREACH:
            return None
        inner = outer + 8
        ihl = (icmp_packet[inner] & 0x0F) * 4
        if icmp_packet[inner + 9] != socket.IPPROTO_UDP:
            return None
        if icmp_packet[inner + 12 : inner + 16] != socket.inet_aton(own):
            return None
        sport, dport, length = struct.unpack_from("!HHH", icmp_packet, inner + ihl)
    except (IndexError, struct.error):
        return None
    if sport != wire.AODV_PORT or dport != wire.AODV_PORT or length < 8:
        return None
    return length, icmp_packet[inner + ihl + 8 : inner + ihl + length]


def _quietly(what: str, fn, *args) -> None:
    """Run one step of the teardown: a failure is logged and the teardown goes on."""
    try:
        fn(*args)
    except Exception as e:
        log.warning("teardown: %s: %s", what, e)


class Daemon:
    def __init__(
        self,
        robot: str,
        iface: str,
        params: Params,
        stats_path: str | None,
        net: str = "10.0.0.0/16",
        state_path: str | None = None,
    ) -> None:
        self.robot = robot
        self.store = CounterStore(state_path) if state_path else None
        self.iface = iface
        self.p = params
        self.stats_path = stats_path
        self.net = ipaddress.IPv4Network(net)
        self._net = int(self.net.network_address)
        self._mask = int(self.net.netmask)
        self._bcast = int(self.net.broadcast_address)
        self._stop = False
        self._dump = False
        self._malformed_logged = 0
        self._hosts: set[str] = set()  # addresses _check_addresses found in our network
        self._poll_started = 0.0
        # When the newest RREQ of our own for each destination went to sendto().
        self._rreq_sent: dict[str, float] = {}
        # Made by run(), in this order, and undone in the reverse order by its ExitStack
        # (declared here, set there: nothing reads them before).
        self.routes: KernelRoutes  # rtnetlink: our kernel routes
        self.addr: str  # our address on `iface`
        self.stats: Stats
        self.tun: Tun  # packets that found no kernel route
        self.monitor: UseMonitor  # nftables set of route uses
        self.reader: SetReader  # reads that set over NETLINK_NETFILTER
        self.sock: socket.socket  # UDP 654, control messages
        self._ttl: int | None = None  # the IP TTL `sock` sends with now
        self.raw: socket.socket  # re-sends buffered packets
        self.icmp: socket.socket  # ICMP errors about our datagrams
        self._wake_r: socket.socket  # signal wake-up (set_wakeup_fd)
        self._wake_w: socket.socket
        self.core: AodvCore | None = None  # None until the end of start-up

    @property
    def _core(self) -> AodvCore:
        """The protocol core, for the loop (which runs only once start-up made it)."""
        assert self.core is not None
        return self.core

    # -- lifecycle -----------------------------------------------------------------------
    def run(self) -> int:
        with contextlib.ExitStack() as undo:
            undo.callback(log.info, "AODV down")
            self._start(undo)
            self._loop()
        return 0

    def _start(self, undo: contextlib.ExitStack) -> None:
        """Make the daemon's kernel objects and sockets, each followed by what undoes it.

        `undo` runs those in reverse order when the daemon stops, however it stops; each
        one's failure is logged and the rest still run. So: the sockets go first (after
        draining what the kernel reported meanwhile), then the route-use reader and the
        nftables set, the TUN device, our routes, the last statistics, rtnetlink."""
        self.routes = KernelRoutes(self.iface)
        undo.callback(_quietly, "close rtnetlink", self.routes.close)
        self.addr = self.routes.address()
        self.stats = Stats(self.robot, self.addr)
        undo.callback(_quietly, "write statistics", self._write_stats)
        stale = self.routes.ours()
        resumed = self.store.load() if self.store else None
        rebooted = bool(stale) or resumed is not None
        if stale:
            log.warning("found %d routes of a previous run: reboot rule applies", len(stale))
        if resumed is not None:
            log.warning(
                "restarted (counters of a previous instance found): waiting DELETE_PERIOD "
                "(%.1f s), sequence number resumes at %d, RREQ ID at %d",
                self.p.delete_period,
                *resumed,
            )
        seq, rreq_id = resumed or (0, 0)
        self.routes.flush()
        undo.callback(_quietly, "flush routes", self.routes.flush)
        self.tun = Tun()
        undo.callback(_quietly, "close the TUN device", self.tun.close)
        self.routes.catch_all(self.tun.ifindex, str(self.net), self.addr)
        self.monitor = UseMonitor(self.iface, str(self.net), self._poll_period())
        undo.callback(_quietly, "remove the route-use set", self.monitor.remove)
        self.reader = SetReader()
        undo.callback(_quietly, "close the route-use reader", self.reader.close)
        self._open_sockets(undo)
        # Exercise the core and the codec before the first real message (sim.warm_up).
        warm_up(self.p)
        gc.collect()
        self.core = AodvCore(
            self.addr, self.p, time.monotonic(), rebooted=rebooted, seq=seq, rreq_id=rreq_id
        )
        if self.store:
            self.store.cover(seq, rreq_id)  # a restart's own file says so from now on
        # What start-up allocated lives for good: keep it out of the collector's
        # full passes, which would otherwise walk it on some discovery's hot path.
        gc.freeze()
        log.info("AODV up on %s (%s), time scale %g", self.iface, self.addr, self.p.time_scale)

    def _poll_period(self) -> float:
        return self.p.active_route_timeout / 3

    def _open_sockets(self, undo: contextlib.ExitStack) -> None:
        s = undo.enter_context(socket.socket(socket.AF_INET, socket.SOCK_DGRAM))
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_BINDTODEVICE, self.iface.encode())
        s.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        s.setsockopt(socket.IPPROTO_IP, IP_RECVTTL, 1)
        s.bind(("0.0.0.0", wire.AODV_PORT))
        drop_own_datagrams(s, self.addr)
        s.setblocking(False)
        self.sock = s
        self.raw = undo.enter_context(
            socket.socket(socket.AF_INET, socket.SOCK_RAW, socket.IPPROTO_RAW)
        )
        self.icmp = undo.enter_context(
            socket.socket(socket.AF_INET, socket.SOCK_RAW, socket.IPPROTO_ICMP)
        )
        self.icmp.setblocking(False)
        # Closed after the others, so what the kernel reported meanwhile is counted.
        undo.callback(_quietly, "read the last ICMP errors", self._on_icmp)
        self._wake_r, self._wake_w = socket.socketpair()
        undo.enter_context(self._wake_r)
        undo.enter_context(self._wake_w)
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)
        signal.set_wakeup_fd(self._wake_w.fileno(), warn_on_full_buffer=False)
        undo.callback(signal.set_wakeup_fd, -1)
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, self._on_stop)
        signal.signal(signal.SIGUSR1, self._on_dump)

    def _on_stop(self, *_a) -> None:
        self._stop = True

    def _on_dump(self, *_a) -> None:
        self._dump = True

    def _write_stats(self) -> None:
        if self.stats_path:
            if self.core is not None:  # None when start-up failed
                self.stats.routes = {
                    d: {"next_hop": nh, "hops": h} for d, (nh, h) in self.core.routes().items()
                }
                self.stats.protocol_dropped = self.core.dropped
            self.stats.write(self.stats_path)

    # -- the loop ------------------------------------------------------------------------
    def _loop(self) -> None:
        # The HELLO and expiry timers are the daemon's deadlines (the fidelity verdict reads
        # how late they fired): real-time priority 1, as each robot's motion control and
        # planner, while the loop serves; back as it was when it ends.
        with deadline_priority(*DEADLINE_PRIORITY), selectors.DefaultSelector() as sel:
            self._serve(sel)

    def _serve(self, sel: selectors.BaseSelector) -> None:
        sel.register(self.sock, selectors.EVENT_READ, self._on_udp)
        sel.register(self.tun.fd, selectors.EVENT_READ, self._on_tun)
        sel.register(self._wake_r, selectors.EVENT_READ, self._on_wake)
        sel.register(self.routes.nl, selectors.EVENT_READ, self._on_netlink)
        sel.register(self.reader.sock, selectors.EVENT_READ, self._on_poll_answer)
        sel.register(self.icmp, selectors.EVENT_READ, self._on_icmp)
        next_poll = time.monotonic() + self._poll_period()
        next_stats = time.monotonic()
        while not self._stop:
            now = time.monotonic()
            deadline = self._core.next_deadline()
            if now >= deadline:
                kind = "hello" if deadline == self._core.next_hello else "expiry"
                late_ms = (now - deadline) * 1000 * self.p.time_scale
                self.stats.timer_lateness[kind].add(late_ms, deadline, now)
                # What already waits in the sockets happened before the timer is handled: a
                # daemon that was descheduled past a neighbour's timeout reads that
                # neighbour's HELLO first, instead of expiring a neighbour that spoke.
                for key, _ in sel.select(0):
                    key.data()
                now = time.monotonic()
                self._execute(self._core.on_timer(now), now)
                deadline = self._core.next_deadline()
            if now >= next_poll:
                next_poll = now + self._poll_period()
                self._poll_use(now)
            if self._dump or now >= next_stats:
                self._dump = False
                next_stats = now + STATS_PERIOD
                self._write_stats()
            for key, _ in sel.select(max(0.0, min(deadline, next_poll, next_stats) - now)):
                key.data()

    def _on_wake(self) -> None:
        try:
            while self._wake_r.recv(64):
                pass
        except BlockingIOError:
            pass

    def _on_netlink(self) -> None:
        for failure in self.routes.read_acks():
            self.stats.dropped["kernel_route_error"] += 1
            log.warning("kernel refused %s", failure)

    def _poll_use(self, now: float) -> None:
        """Ask for the nftables set of used addresses, unless a request is under way.

        The answer is read by the loop (`_on_poll_answer`) over NETLINK_NETFILTER, so
        the loop never blocks on it (forking `nft` stalled discoveries by milliseconds)."""
        if self.reader.busy and now - self._poll_started > 5 * self._poll_period():
            log.warning("route-use poll got no answer; asking again")
            self.reader.busy = False
        if self.reader.busy or not self._core.routes():
            return
        try:
            self.reader.request()
        except OSError as e:
            log.warning("route-use poll failed: %s", e)
            return
        self._poll_started = now

    def _on_poll_answer(self) -> None:
        try:
            used = self.reader.receive()
        except (KernelError, OSError) as e:
            self.reader.busy = False
            log.warning("route-use poll: %s", e)
            return
        if used is None:
            return
        now = time.monotonic()
        for addr in used:
            self.stats.route_uses += 1
            self._execute(self._core.on_route_used(self._poll_started, addr), now)

    def _on_udp(self) -> None:
        for _ in range(64):
            try:
                data, anc, _flags, (src, _port) = self.sock.recvmsg(4096, socket.CMSG_SPACE(4))
            except BlockingIOError:
                return
            if src == self.addr:
                continue  # our own broadcast
            ttl = 0
            for level, ctype, cdata in anc:
                if level == socket.IPPROTO_IP and ctype == IP_TTL_CMSG and len(cdata) >= 4:
                    ttl = _I32.unpack_from(cdata)[0]
            self.stats.bytes_received += len(data)
            try:
                msg = wire.decode(data)
                self._check_addresses(src, msg)
            except wire.MalformedPacket as e:
                self._drop("malformed", src, e)
                continue
            kind = "HELLO" if wire.is_hello(msg, src) else msg.type_name
            self.stats.received[kind] += 1
            now = time.monotonic()
            try:
                self._execute(self._core.on_control(now, src, ttl, msg), now)
            except Exception:  # a bug must not kill the daemon; count it loudly
                self.stats.dropped["error"] += 1
                log.exception("error handling %s from %s", kind, src)

    def _on_icmp(self) -> None:
        """ICMP errors about datagrams of ours: the kernel took a message (`_send` counted it
        as sent) but never transmitted it. A unicast to a neighbour whose ARP failed (the
        link broke) is dropped with an ICMP host unreachable to its sender, here through lo.
        The UDP socket cannot be told (IP_RECVERR finds no socket bound to wlan0 for an
        error that arrives on lo), so a raw ICMP socket reads them. Counted by kind as not
        transmitted: sent minus not transmitted is what went on the air, as a capture of
        wlan0 sees it."""
        for _ in range(64):
            try:
                data = self.icmp.recv(2048)
            except BlockingIOError:
                return
            quoted = quoted_datagram(data, self.addr)
            if quoted is None:
                continue
            udp_len, payload = quoted
            try:
                kind = wire.decode(payload).type_name
            except wire.MalformedPacket:
                kind = "unknown"
            self.stats.not_transmitted[kind] += 1
            self.stats.bytes_not_transmitted += udp_len - 8
            log.info("a %s of ours was not transmitted (ICMP destination unreachable)", kind)

    def _check_addresses(self, src: str, msg: wire.Message) -> None:
        """Every address a peer names must be a host of our network (integer math: the
        ipaddress module cost 50 us a message; addresses that passed are remembered, as a
        few robots' addresses come back in every message)."""
        addrs: tuple[str, ...]
        if isinstance(msg, (wire.Rreq, wire.Rrep)):
            addrs = (src, msg.dest, msg.orig)
        elif isinstance(msg, wire.Rerr):
            addrs = (src, *(a for a, _ in msg.unreachable))
        else:
            addrs = (src,)
        hosts = self._hosts
        for a in addrs:
            if a in hosts:
                continue
            ip = _U32.unpack(socket.inet_aton(a))[0]
            if ip & self._mask != self._net or ip in (self._net, self._bcast):
                raise wire.MalformedPacket(f"address {a} outside {self.net}")
            if len(hosts) >= HOSTS_REMEMBERED:
                hosts.clear()
            hosts.add(a)

    def _drop(self, reason: str, src: str, err: Exception) -> None:
        self.stats.dropped[reason] += 1
        self._malformed_logged += 1
        n = self._malformed_logged
        if n <= 10 or n % 10000 == 0:
            log.warning("dropped %s datagram from %s (%d so far): %s", reason, src, n, err)

    def _on_tun(self) -> None:
        for _ in range(256):
            pkt = self.tun.read()
            if pkt is None:
                return
            if len(pkt) < 20 or pkt[0] >> 4 != 4:
                self.stats.dropped["tun_not_ipv4"] += 1
                continue
            src = socket.inet_ntoa(pkt[12:16])
            dst = socket.inet_ntoa(pkt[16:20])
            if _U32.unpack_from(pkt, 16)[0] & self._mask != self._net:
                self.stats.dropped["tun_foreign"] += 1
                continue
            if src == self.addr:
                self.stats.packets_buffered += 1
            now = time.monotonic()
            self._execute(self._core.on_no_route(now, src, dst, pkt), now)

    # -- actions -------------------------------------------------------------------------
    def _execute(self, actions: list, now: float) -> None:
        if self.store:
            # RFC 6.13: the numbers these messages carry are on disk before they leave.
            self.store.cover(self._core.seq, self._core.rreq_id)
        routed = now  # when the last route change of this batch was in the kernel
        # In the core's order (AodvCore._finish): control messages, route changes,
        # releases, RREP-ACKs. Installs are rtnetlink writes whose acknowledgements the
        # loop reads later (`_on_netlink`). Route changes are logged at DEBUG: at INFO
        # the line cost more than the netlink request on a discovery's critical path.
        for a in actions:
            if isinstance(a, Unicast):
                self._send(a.msg, a.dst, a.ttl, socket.MSG_DONTROUTE)
            elif isinstance(a, Broadcast):
                self._send(a.msg, BROADCAST, a.ttl, 0)
            elif isinstance(a, InstallRoute):
                self.routes.install(a.dest, a.next_hop)
                routed = time.monotonic()
                self.stats.route_installs += 1
                log.debug("route %s via %s (%d hops)", a.dest, a.next_hop, a.hops)
            elif isinstance(a, DeleteRoute):
                self.routes.delete(a.dest)
                routed = time.monotonic()
                self.stats.route_deletes += 1
                log.debug("route %s deleted", a.dest)
            elif isinstance(a, ReleasePackets):
                for pkt in a.packets:
                    try:
                        self.raw.sendto(pkt, (a.dest, 0))
                        self.stats.packets_released += 1
                    except OSError as e:
                        self.stats.dropped["release_failed"] += 1
                        log.warning("re-send to %s failed: %s", a.dest, e)
            elif isinstance(a, DropPackets):
                for pkt in a.packets:
                    if pkt[12:16] == socket.inet_aton(self.addr):
                        self.tun.write(icmp_host_unreachable(self.addr, pkt))
                        self.stats.icmp_unreachable += 1
            elif isinstance(a, DiscoveryDone) and a.repair:
                self.stats.local_repairs["ok" if a.ok else "failed"] += 1
                log.info("local repair of %s %s", a.dest, "succeeded" if a.ok else "failed")
            elif isinstance(a, DiscoveryDone):
                # Both latencies end when the route is in the kernel (the core's run to
                # `now`, the install took until `routed`). The round starts when the RREQ
                # that succeeded went to sendto() (the core's round starts at the event
                # that made it send, before the core ran and the RREQ was encoded).
                extra = routed - now
                sent = self._rreq_sent.pop(a.dest, None)
                rnd = a.round_latency + extra if sent is None else routed - sent
                self.stats.discoveries.append(
                    {
                        "dest": a.dest,
                        "ok": a.ok,
                        "latency_s": round(a.latency + extra, 6),
                        "round_latency_s": round(rnd, 6),
                        "t": round(time.time(), 3),
                    }
                )
                log.info(
                    "discovery of %s %s after %.1f ms",
                    a.dest,
                    "succeeded" if a.ok else "failed",
                    1000 * (a.latency + extra),
                )

    def _send(self, msg: wire.Message, dst: str, ttl: int, flags: int) -> None:
        try:
            data = wire.encode(msg)
        except ValueError as e:  # a core bug: count it, and let the route actions run
            self.stats.dropped["encode_failed"] += 1
            log.error("could not encode %s to %s: %s", msg.type_name, dst, e)
            return
        if ttl != self._ttl:
            self.sock.setsockopt(socket.IPPROTO_IP, socket.IP_TTL, ttl)
            self._ttl = ttl
        if isinstance(msg, wire.Rreq) and msg.orig == self.addr:
            self._rreq_sent[msg.dest] = time.monotonic()
        try:
            self.sock.sendto(data, flags, (dst, wire.AODV_PORT))
        except OSError as e:
            self.stats.dropped["send_failed"] += 1
            log.warning("send %s to %s failed: %s", msg.type_name, dst, e)
            return
        kind = "HELLO" if wire.is_hello(msg, self.addr) else msg.type_name
        self.stats.sent[kind] += 1
        self.stats.bytes_sent += len(data)
