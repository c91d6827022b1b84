"""Kernel objects the AODV daemon owns inside its robot's namespace.

- `KernelRoutes`: /32 routes of our own routing protocol number. Neighbours are
  `dev wlan0 scope link`, others `via NEXT dev wlan0 onlink`. Requests are rtnetlink
  messages (packed by topology/kernel/netlinkmsg.py) written to a raw NETLINK_ROUTE socket. At
  run time installs and deletes ask for no acknowledgement: the kernel applies a route
  request within the send() call, so a packet sent right after sees the route, and it
  answers a request without NLM_F_ACK only when the request failed; the daemon's loop
  wakes on that answer and `read_acks` names the failed request. (Asking for every
  acknowledgement cost one more loop turn per discovery hop.) Start-up and teardown
  requests ask and wait. (pyroute2's IPRoute costs ~1.5 ms a request, more than a
  discovery hop, and its import 18 MB and half a second per daemon: the daemon does not
  use it.)
- `Tun`: the TUN device that catches packets with no route (a 10.0.0.0/16 route points at
  it, less specific than every /32), IPv6 disabled on it.
- `UseMonitor`: an nftables table whose dynamic set collects the addresses of data packets
  sent, received and forwarded through wlan0; the daemon polls it to refresh lifetimes of
  routes in use (RFC 3561 6.2) without per-packet Python.

Every failure of a kernel command raises `KernelError` carrying the command's message.
"""

from __future__ import annotations

import ctypes
import errno
import fcntl
import ipaddress
import json
import logging
import os
import select
import socket
import struct
import subprocess
import threading

from topology.kernel import netlinkmsg as nl

log = logging.getLogger(__name__)

# Our routing protocol number in `ip route` (rt_protos has babel at 42); unassigned.
RTPROT_AODV = 101
TUN_NAME = "aodv0"
NFT_TABLE = "aodv"

_SIOCGIFFLAGS, _SIOCSIFFLAGS, _SIOCGIFADDR = 0x8913, 0x8914, 0x8915
_IFF_UP = 0x1
_TUNSETIFF = 0x400454CA
_IFF_TUN = 0x0001
_IFF_NO_PI = 0x1000


_SO_ATTACH_FILTER = 26
_SKF_NET_OFF = -0x100000
_BPF_LD_W_ABS, _BPF_JEQ_K, _BPF_RET_K = 0x20, 0x15, 0x06
_SOCK_FILTER = struct.Struct("=HBBI")


def drop_own_datagrams(sock: socket.socket, own: str) -> None:
    """Attach a socket filter that drops datagrams whose IP source is `own`.

    The kernel loops every broadcast we send back to our own socket; dropped there, it
    costs no wake-up and no receive call. The program (classic BPF): load the IP source
    address (SKF_NET_OFF + 12), equal to `own`? return 0 (drop), else accept all."""
    prog = b"".join(
        _SOCK_FILTER.pack(*insn)
        for insn in (
            (_BPF_LD_W_ABS, 0, 0, (_SKF_NET_OFF + 12) & 0xFFFFFFFF),
            (_BPF_JEQ_K, 1, 0, struct.unpack("!I", socket.inet_aton(own))[0]),
            (_BPF_RET_K, 0, 0, 0xFFFFFFFF),
            (_BPF_RET_K, 0, 0, 0),
        )
    )
    buf = ctypes.create_string_buffer(prog)
    fprog = struct.pack("HL", len(prog) // _SOCK_FILTER.size, ctypes.addressof(buf))
    try:
        sock.setsockopt(socket.SOL_SOCKET, _SO_ATTACH_FILTER, fprog)
    except OSError as e:
        raise KernelError(f"socket filter: {e}") from e


class KernelError(RuntimeError):
    """A kernel operation failed; the message carries the kernel's or tool's error."""


def write_sysctl(path: str, value: str) -> None:
    try:
        with open(f"/proc/sys/{path.replace('.', '/')}", "w") as f:
            f.write(value)
    except OSError as e:
        raise KernelError(f"sysctl {path}={value}: {e}") from e


def ifindex(name: str) -> int:
    try:
        return socket.if_nametoindex(name)
    except OSError:
        raise KernelError(f"no interface {name}") from None


def ipv4_address(name: str) -> str:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            res = fcntl.ioctl(s.fileno(), _SIOCGIFADDR, struct.pack("16s16x", name.encode()))
        except OSError:
            raise KernelError(f"{name} has no IPv4 address") from None
    return socket.inet_ntoa(res[20:24])


def set_up(name: str) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        req = struct.pack("16sH14x", name.encode(), 0)
        flags = struct.unpack_from("H", fcntl.ioctl(s.fileno(), _SIOCGIFFLAGS, req), 16)[0]
        fcntl.ioctl(
            s.fileno(), _SIOCSIFFLAGS, struct.pack("16sH14x", name.encode(), flags | _IFF_UP)
        )


class KernelRoutes:
    PENDING_MAX = 1024

    def __init__(self, ifname: str) -> None:
        self.ifindex = ifindex(ifname)
        self.ifname = ifname
        self.nl = socket.socket(socket.AF_NETLINK, socket.SOCK_RAW, socket.NETLINK_ROUTE)
        self.nl.bind((0, 0))
        self.nl.setblocking(False)
        self._seq = 0
        # What each recent request was, to name the one an error is about. Requests sent
        # without NLM_F_ACK are answered only on failure, at once (within send()): only
        # the newest PENDING_MAX are kept.
        self._pending: dict[int, str] = {}
        # Requests are sent by the actuator's kernel thread and answered on the loop's.
        self._pending_lock = threading.Lock()
        self.errors = 0

    # -- raw rtnetlink ---------------------------------------------------------------------
    def _next_seq(self, what: str) -> int:
        """The sequence number of a new request, remembered with what the request is."""
        with self._pending_lock:
            self._seq += 1
            self._pending[self._seq] = what
            if len(self._pending) > self.PENDING_MAX:
                del self._pending[next(iter(self._pending))]
            return self._seq

    def _send(self, request: bytes, what: str) -> None:
        try:
            self.nl.send(request)
        except OSError as e:
            raise KernelError(f"{what}: {e}") from e

    def _messages(self, timeout: float | None = 0.0):
        """(type, seq, data, payload start, payload end) of every netlink message readable
        now (or within timeout)."""
        if timeout and not select.select([self.nl], [], [], timeout)[0]:
            return
        while True:
            try:
                data = self.nl.recv(1 << 16)
            except BlockingIOError:
                return
            for mtype, seq, start, end in nl.messages(data):
                yield mtype, seq, data, start, end

    def _ack(self, seq: int, data: bytes, start: int) -> str | None:
        """The failure an NLMSG_ERROR carries, or None for an acknowledgement."""
        code = nl.error_code(data, start)
        with self._pending_lock:
            what = self._pending.pop(seq, "?")
        if code and code not in (errno.ESRCH, errno.ENOENT):
            self.errors += 1
            return f"{what}: {os.strerror(code)}"
        return None

    def read_acks(self) -> list[str]:
        """Read the kernel's answers that arrived; return one message per failed request."""
        failures = []
        for mtype, seq, data, start, end in self._messages():
            if mtype == nl.NLMSG_ERROR and end - start >= 4:
                failure = self._ack(seq, data, start)
                if failure:
                    failures.append(failure)
        return failures

    def _wait(self, seq: int) -> None:
        """Block (up to 5 s) for the acknowledgement of request `seq`; raise its error."""
        for _ in range(100):
            for mtype, mseq, data, start, end in self._messages(timeout=0.05):
                if mtype == nl.NLMSG_ERROR and end - start >= 4:
                    failure = self._ack(mseq, data, start)
                    if mseq == seq:
                        if failure:
                            raise KernelError(failure)
                        return
                    if failure:
                        log.warning("kernel refused %s", failure)
        raise KernelError(f"no answer from the kernel to {self._pending.pop(seq, '?')}")

    # -- routes ----------------------------------------------------------------------------
    def address(self) -> str:
        return ipv4_address(self.ifname)

    def ours(self) -> list[tuple[str, int]]:
        """(destination, prefix length) of routes with our protocol number, any table."""
        self.read_acks()
        self._seq += 1
        seq = self._seq
        self._send(nl.route_dump(seq), "dump")
        found: list[tuple[str, int]] = []
        for _ in range(100):
            for mtype, mseq, data, start, end in self._messages(timeout=0.05):
                if mseq != seq:
                    continue
                if mtype in (nl.NLMSG_DONE, nl.NLMSG_ERROR):
                    return found
                if mtype != nl.RTM_NEWROUTE:
                    continue
                route = nl.parse_route(data, start, end)
                if route is None or route.proto != RTPROT_AODV:
                    continue
                found.append((route.dst or "0.0.0.0", route.dst_len))
        raise KernelError("route dump did not finish")

    def flush(self) -> int:
        """Delete every route with our protocol number; return how many there were."""
        found = self.ours()
        for dst, plen in found:
            self._wait(self.delete(dst, plen, ack=True))
        return len(found)

    def install(self, dest: str, next_hop: str, ack: bool = False) -> int:
        """`ip route replace DEST/32 [via NEXT onlink] dev IFACE proto RTPROT_AODV`.

        Returns the request's sequence number. Without `ack` the kernel answers only if the
        request failed (`read_acks`); with it, always (`_wait` needs that)."""
        what = f"route {dest} via {next_hop}"
        seq = self._next_seq(what)
        self._send(nl.route_replace(dest, next_hop, self.ifindex, RTPROT_AODV, ack=ack, seq=seq),
                   what)  # fmt: skip
        return seq

    def delete(self, dest: str, plen: int = 32, ack: bool = False) -> int:
        """`ip route del DEST/PLEN proto RTPROT_AODV`; a route already gone is no error.
        `ack` as for `install`."""
        what = f"delete route {dest}"
        seq = self._next_seq(what)
        self._send(nl.route_delete(dest, RTPROT_AODV, plen=plen, ack=ack, seq=seq), what)
        return seq

    def catch_all(self, oif: int, net: str, src: str) -> None:
        """`ip route replace NET dev TUN src SRC metric 1000 proto RTPROT_AODV`: packets
        without a /32 route go to the TUN device."""
        n = ipaddress.IPv4Network(net)
        what = f"route {net} dev TUN"
        seq = self._next_seq(what)
        flags = nl.NLM_F_REQUEST | nl.NLM_F_ACK | nl.NLM_F_REPLACE | nl.NLM_F_CREATE
        self._send(
            nl.route_message(
                nl.RTM_NEWROUTE, flags, str(n.network_address), plen=n.prefixlen,
                proto=RTPROT_AODV, scope=nl.RT_SCOPE_LINK, oif=oif, prefsrc=src, priority=1000,
                seq=seq,
            ),
            what,
        )  # fmt: skip
        self._wait(seq)

    def close(self) -> None:
        self.nl.close()


class Tun:
    """A TUN device (no packet info header) that exists while this object is open."""

    def __init__(self, name: str = TUN_NAME) -> None:
        try:
            self.fd = os.open("/dev/net/tun", os.O_RDWR | os.O_NONBLOCK)
            fcntl.ioctl(
                self.fd, _TUNSETIFF, struct.pack("16sH", name.encode(), _IFF_TUN | _IFF_NO_PI)
            )
        except OSError as e:
            raise KernelError(f"create TUN {name}: {e}") from e
        self.name = name
        # docs/architecture.md: the daemon ignores IPv6 and disables it on its own TUN device.
        write_sysctl(f"net.ipv6.conf.{name}.disable_ipv6", "1")
        # ICMP errors we inject come from our own address: accept them on the TUN.
        write_sysctl(f"net.ipv4.conf.{name}.accept_local", "1")
        write_sysctl(f"net.ipv4.conf.{name}.rp_filter", "0")
        self.ifindex = ifindex(name)
        set_up(name)

    def read(self) -> bytes | None:
        try:
            return os.read(self.fd, 65535)
        except BlockingIOError:
            return None

    def write(self, packet: bytes) -> None:
        os.write(self.fd, packet)

    def close(self) -> None:
        os.close(self.fd)


_NETLINK_NETFILTER = 12


class SetReader:
    """Reads the elements of our nftables set over NETLINK_NETFILTER, without blocking.

    `request()` sends a dump request; when the socket is readable, `receive()` parses what
    arrived and returns the addresses once the dump is complete (None before). No `nft`
    process is forked: a poll costs tens of microseconds instead of milliseconds."""

    def __init__(self, table: str = NFT_TABLE, set_name: str = "used") -> None:
        self.sock = socket.socket(socket.AF_NETLINK, socket.SOCK_RAW, _NETLINK_NETFILTER)
        self.sock.bind((0, 0))
        self.sock.setblocking(False)
        self.table, self.set_name = table, set_name
        self._seq = 0
        self._found: list[str] = []
        self.busy = False

    def request(self) -> None:
        self._seq += 1
        self._found = []
        self.sock.send(nl.set_elements_dump(self.table, self.set_name, self._seq))
        self.busy = True

    def receive(self) -> list[str] | None:
        while True:
            try:
                data = self.sock.recv(1 << 16)
            except BlockingIOError:
                return None
            for mtype, seq, start, end in nl.messages(data):
                if seq != self._seq:
                    continue
                if mtype in (nl.NLMSG_DONE, nl.NLMSG_ERROR):
                    self.busy = False
                    if mtype == nl.NLMSG_ERROR and end - start >= 4:
                        code = nl.error_code(data, start)
                        if code:
                            raise KernelError(f"nftables set read: {os.strerror(code)}")
                    return self._found
                if mtype == nl.NFT_MSG_NEWSETELEM:
                    self._found += nl.set_element_addresses(data, start, end)

    def close(self) -> None:
        self.sock.close()


class UseMonitor:
    """nftables dynamic set of addresses seen in data packets on `ifname`."""

    def __init__(self, ifname: str, net: str, period: float) -> None:
        ms = max(1, int(period * 1000))
        self.ruleset = f"""
table ip {NFT_TABLE} {{
    set used {{ type ipv4_addr; flags dynamic,timeout; timeout {ms}ms; }}
    chain use_forward {{
        type filter hook forward priority 0; policy accept;
        ip daddr {net} update @used {{ ip daddr }}
        ip saddr {net} update @used {{ ip saddr }}
    }}
    chain use_output {{
        type filter hook output priority 0; policy accept;
        oifname "{ifname}" udp dport 654 return
        oifname "{ifname}" ip daddr {net} update @used {{ ip daddr }}
    }}
    chain use_input {{
        type filter hook input priority 0; policy accept;
        iifname "{ifname}" udp dport 654 return
        iifname "{ifname}" ip saddr {net} update @used {{ ip saddr }}
    }}
}}
"""
        # One nft and one atomic batch: the table added (a no-op when a crashed daemon's is
        # there) and deleted, so that the ruleset replaces any leftover, then the ruleset. Not
        # `delete` on its own first: in a fresh namespace it fails, and costs a second nft.
        self._nft(
            ["-f", "-"], f"add table ip {NFT_TABLE}\ndelete table ip {NFT_TABLE}\n" + self.ruleset
        )

    @staticmethod
    def _nft(args: list[str], stdin: str | None = None) -> str:
        proc = subprocess.run(
            ["nft", *args], input=stdin, capture_output=True, text=True, check=False
        )
        if proc.returncode != 0:
            raise KernelError(f"nft {' '.join(args)}: {proc.stderr.strip()}")
        return proc.stdout

    def poll(self) -> list[str]:
        """Read the set, blocking (tests and tools)."""
        return self.parse(self._nft(["-j", "list", "set", "ip", NFT_TABLE, "used"]))

    @staticmethod
    def parse(text: str) -> list[str]:
        """Addresses in `nft -j list set` output."""
        out = json.loads(text)
        addrs = []
        for item in out.get("nftables", []):
            for e in item.get("set", {}).get("elem", []) or []:
                if isinstance(e, dict):
                    e = e.get("elem", {}).get("val")
                if isinstance(e, str):
                    addrs.append(e)
        return addrs

    def remove(self) -> None:
        subprocess.run(
            ["nft", "delete", "table", "ip", NFT_TABLE], capture_output=True, check=False
        )
