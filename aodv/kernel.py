"""Kernel objects the AODV daemon owns inside its robot's namespace.

- `KernelRoutes`: /32 routes of our own routing protocol number. Neighbours are
  `dev wlan0 scope link`, others `via NEXT dev wlan0 onlink`. Installs and deletes are
  rtnetlink messages packed here and written to a raw NETLINK_ROUTE socket without waiting
  for the acknowledgement (pyroute2's IPRoute costs ~1.5 ms a request, more than a whole
  discovery hop); the kernel applies a route request within the send() call, so a packet
  sent right after sees the route. Acknowledgements are read by the daemon's loop
  (`read_acks`), and errors logged there. Start-up and flushing use pyroute2.
- `Tun`: the TUN device that catches packets with no route (a 10.0.0.0/16 route points at
  it, less specific than every /32), IPv6 disabled on it.
- `UseMonitor`: an nftables table whose dynamic set collects the addresses of data packets
  sent, received and forwarded through wlan0; the daemon polls it to refresh lifetimes of
  routes in use (RFC 3561 6.2) without per-packet Python.

Every failure of a kernel command raises `KernelError` carrying the command's message.
"""

from __future__ import annotations

import errno
import fcntl
import json
import logging
import os
import socket
import struct
import subprocess

from pyroute2 import IPRoute
from pyroute2.netlink.exceptions import NetlinkError

log = logging.getLogger(__name__)

# Our routing protocol number in `ip route` (rt_protos has babel at 42); unassigned.
RTPROT_AODV = 101
RTNH_F_ONLINK = 4
RT_SCOPE_LINK = 253
TUN_NAME = "aodv0"
NFT_TABLE = "aodv"

_NLMSGHDR = struct.Struct("=LHHLL")
_RTMSG = struct.Struct("=BBBBBBBBI")
_RTA = struct.Struct("=HH")
_RTM_NEWROUTE, _RTM_DELROUTE = 24, 25
_NLMSG_ERROR = 2
_NLM_F_REQUEST, _NLM_F_ACK, _NLM_F_REPLACE, _NLM_F_CREATE = 0x1, 0x4, 0x100, 0x400
_RTA_DST, _RTA_OIF, _RTA_GATEWAY = 1, 4, 5
_RT_TABLE_MAIN, _RTN_UNICAST, _RT_SCOPE_UNIVERSE, _RT_SCOPE_NOWHERE = 254, 1, 0, 255

_TUNSETIFF = 0x400454CA
_IFF_TUN = 0x0001
_IFF_NO_PI = 0x1000


class KernelError(RuntimeError):
    """A kernel operation failed; the message carries the kernel's or tool's error."""


def write_sysctl(path: str, value: str) -> None:
    try:
        with open(f"/proc/sys/{path.replace('.', '/')}", "w") as f:
            f.write(value)
    except OSError as e:
        raise KernelError(f"sysctl {path}={value}: {e}") from e


class KernelRoutes:
    def __init__(self, ifname: str) -> None:
        self.ipr = IPRoute()
        found = self.ipr.link_lookup(ifname=ifname)
        if not found:
            raise KernelError(f"no interface {ifname}")
        self.ifindex = found[0]
        self.ifname = ifname
        self.nl = socket.socket(socket.AF_NETLINK, socket.SOCK_RAW, socket.NETLINK_ROUTE)
        self.nl.bind((0, 0))
        self.nl.setblocking(False)
        self._seq = 0
        self._pending: dict[int, str] = {}
        self.errors = 0

    def _request(self, rtm_type: int, flags: int, rtmsg: bytes, attrs: bytes, what: str) -> None:
        self._seq += 1
        body = rtmsg + attrs
        hdr = _NLMSGHDR.pack(_NLMSGHDR.size + len(body), rtm_type, flags, self._seq, 0)
        self._pending[self._seq] = what
        try:
            self.nl.send(hdr + body)
        except OSError as e:
            raise KernelError(f"{what}: {e}") from e

    @staticmethod
    def _attr(kind: int, data: bytes) -> bytes:
        return _RTA.pack(_RTA.size + len(data), kind) + data  # all ours are 4-byte aligned

    def read_acks(self) -> list[str]:
        """Read pending acknowledgements; return one message per failed request."""
        failures = []
        while True:
            try:
                data = self.nl.recv(65536)
            except BlockingIOError:
                return failures
            off = 0
            while off + _NLMSGHDR.size <= len(data):
                length, mtype, _flags, seq, _pid = _NLMSGHDR.unpack_from(data, off)
                if mtype == _NLMSG_ERROR and length >= _NLMSGHDR.size + 4:
                    code = -struct.unpack_from("=i", data, off + _NLMSGHDR.size)[0]
                    what = self._pending.pop(seq, "?")
                    if code and code not in (errno.ESRCH, errno.ENOENT):
                        self.errors += 1
                        failures.append(f"{what}: {os.strerror(code)}")
                if length == 0:
                    break
                off += (length + 3) & ~3

    def address(self) -> str:
        addrs = self.ipr.get_addr(index=self.ifindex, family=2)
        if not addrs:
            raise KernelError(f"{self.ifname} has no IPv4 address")
        return addrs[0].get("address")

    def ours(self) -> list[str]:
        """Destinations of routes with our protocol number (a previous run's, at start)."""
        return [r.get("dst") for r in self.ipr.get_routes(family=2, proto=RTPROT_AODV)]

    def flush(self) -> int:
        """Delete every route with our protocol number; return how many there were."""
        found = [
            (r.get("dst"), r["dst_len"]) for r in self.ipr.get_routes(family=2, proto=RTPROT_AODV)
        ]
        for dst, plen in found:
            self.delete(dst, plen)
        failures = self.read_acks()
        if failures:
            raise KernelError("; ".join(failures))
        return len(found)

    def install(self, dest: str, next_hop: str) -> None:
        """`ip route replace DEST/32 [via NEXT onlink] dev IFACE proto RTPROT_AODV`."""
        attrs = self._attr(_RTA_DST, socket.inet_aton(dest)) + self._attr(
            _RTA_OIF, struct.pack("=I", self.ifindex)
        )
        if next_hop == dest:
            scope, rflags = RT_SCOPE_LINK, 0
        else:
            scope, rflags = _RT_SCOPE_UNIVERSE, RTNH_F_ONLINK
            attrs += self._attr(_RTA_GATEWAY, socket.inet_aton(next_hop))
        rtmsg = _RTMSG.pack(
            socket.AF_INET, 32, 0, 0, _RT_TABLE_MAIN, RTPROT_AODV, scope, _RTN_UNICAST, rflags
        )
        flags = _NLM_F_REQUEST | _NLM_F_ACK | _NLM_F_REPLACE | _NLM_F_CREATE
        self._request(_RTM_NEWROUTE, flags, rtmsg, attrs, f"route {dest} via {next_hop}")

    def delete(self, dest: str, plen: int = 32) -> None:
        """`ip route del DEST/PLEN proto RTPROT_AODV`; a route already gone is no error."""
        rtmsg = _RTMSG.pack(
            socket.AF_INET, plen, 0, 0, _RT_TABLE_MAIN, RTPROT_AODV, _RT_SCOPE_NOWHERE, 0, 0
        )
        attrs = self._attr(_RTA_DST, socket.inet_aton(dest))
        self._request(
            _RTM_DELROUTE, _NLM_F_REQUEST | _NLM_F_ACK, rtmsg, attrs, f"delete route {dest}"
        )

    def catch_all(self, ifindex: int, net: str, src: str) -> None:
        """The route that sends packets without a /32 route to the TUN device."""
        try:
            self.ipr.route(
                "replace", dst=net, oif=ifindex, prefsrc=src, proto=RTPROT_AODV, priority=1000
            )
        except NetlinkError as e:
            raise KernelError(f"route {net} dev {TUN_NAME}: {e}") from e

    def close(self) -> None:
        self.nl.close()
        self.ipr.close()


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
        # DESIGN: the daemon ignores IPv6 and disables it on its own TUN device.
        write_sysctl(f"net.ipv6.conf.{name}.disable_ipv6", "1")
        # ICMP errors we inject come from our own address: accept them on the TUN.
        write_sysctl(f"net.ipv4.conf.{name}.accept_local", "1")
        write_sysctl(f"net.ipv4.conf.{name}.rp_filter", "0")
        with IPRoute() as ipr:
            self.ifindex = ipr.link_lookup(ifname=name)[0]
            ipr.link("set", index=self.ifindex, state="up")

    def read(self) -> bytes | None:
        try:
            return os.read(self.fd, 65535)
        except BlockingIOError:
            return None

    def write(self, packet: bytes) -> None:
        os.write(self.fd, packet)

    def close(self) -> None:
        os.close(self.fd)


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
        self.remove()
        self._nft(["-f", "-"], self.ruleset)

    @staticmethod
    def _nft(args: list[str], stdin: str | None = None) -> str:
        proc = subprocess.run(
            ["nft", *args], input=stdin, capture_output=True, text=True, check=False
        )
        if proc.returncode != 0:
            raise KernelError(f"nft {' '.join(args)}: {proc.stderr.strip()}")
        return proc.stdout

    def poll(self) -> list[str]:
        out = json.loads(self._nft(["-j", "list", "set", "ip", NFT_TABLE, "used"]))
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
