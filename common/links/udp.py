"""udpin and udpout links: datagrams, never blocking, never sharing a port.

udpin binds and answers every peer heard recently (a bounded `PeerTable`); udpout sends to
one address and reads only its replies (datagrams from any other address are dropped and
counted in `foreign_datagrams`, so no other process can pose as the peer)."""

from __future__ import annotations

import errno
import ipaddress
import socket
import time
from typing import cast

from common.links.base import RECV_BATCH, Address, Link, bind_error
from common.links.errors import LinkError
from common.links.peers import PeerTable
from common.links.url import LinkUrl

_BROADCAST = ipaddress.IPv4Address("255.255.255.255")


def resolve(url: LinkUrl) -> Address:
    """HOST:PORT as the IPv4 address datagrams come from; LinkError if HOST is unknown."""
    try:
        infos = socket.getaddrinfo(url.host, url.port, socket.AF_INET, socket.SOCK_DGRAM)
    except (socket.gaierror, UnicodeError) as exc:
        raise LinkError(f"link '{url}': cannot resolve {url.host}: {exc}") from None
    host, port = infos[0][4][:2]
    return str(host), int(port)


def is_unicast(host: str) -> bool:
    """An address whose replies come from itself (not a group, broadcast or 0.0.0.0)."""
    addr = ipaddress.IPv4Address(host)
    return not (addr.is_multicast or addr.is_unspecified or addr == _BROADCAST)


class UdpLink(Link):
    """udpin (bind, answer recent peers) or udpout (send to one address, read its replies)."""

    def __init__(self, url: LinkUrl, peer_timeout_s: float = 5.0, max_peers: int = 32) -> None:
        self.url = url
        self._peers = PeerTable(peer_timeout_s, max_peers)
        self.foreign_datagrams = 0  # udpout: datagrams from others than the target, dropped
        target = resolve(url) if url.scheme == "udpout" else None
        # Never SO_REUSEADDR or SO_REUSEPORT: on Linux either lets a second process bind a
        # udpin port and silently take half of its datagrams (pymavlink sets SO_REUSEADDR);
        # here the second one is told the port is in use.
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        try:
            if url.scheme == "udpin":
                self.sock.bind((url.host, url.port))
                self.target: Address | None = None
            else:
                self.sock.bind(("127.0.0.1" if url.host.startswith("127.") else "", 0))
                self.target = target
        except OSError as exc:
            self.sock.close()
            raise bind_error(url, exc) from None
        # Replies come from the address we send to, unless that is a group or broadcast.
        self._only = target if target is not None and is_unicast(target[0]) else None
        self.sock.setblocking(False)

    @property
    def peer_timeout_s(self) -> float:
        return self._peers.timeout_s

    @property
    def max_peers(self) -> int:
        return self._peers.max_peers

    @property
    def unanswered_peers(self) -> int:
        """udpin: new peers not answered because the table was full."""
        return self._peers.unanswered

    @property
    def local_port(self) -> int:
        port: int = self.sock.getsockname()[1]
        return port

    def fileno(self) -> int:
        return self.sock.fileno()

    def recv(self, limit: int = RECV_BATCH) -> list[tuple[object, bytes]]:
        out: list[tuple[object, bytes]] = []
        now = time.monotonic()
        for _ in range(limit):
            try:
                data, addr = self.sock.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                return out
            except ConnectionRefusedError:
                continue  # ICMP from a peer that went away: nothing to read
            if self.target is None:
                self._peers.add(addr, now)
            elif self._only is not None and addr[:2] != self._only:
                self.foreign_datagrams += 1  # not our peer's: nobody else talks on this link
                continue
            out.append((addr, data))
        return out

    def send(self, data: bytes) -> None:
        if self.target is not None:
            self._sendto(data, self.target)
            return
        self._peers.expire(time.monotonic())
        for addr in self._peers.heard:
            self._sendto(data, addr)

    def send_to(self, data: bytes, peer: object) -> None:
        """Send to one peer that `recv` returned (an answer to its sender only)."""
        self._sendto(data, cast(Address, peer))  # recv's peers are recvfrom's addresses

    def _sendto(self, data: bytes, addr: Address) -> None:
        try:
            self.sock.sendto(data, addr)
        except (BlockingIOError, ConnectionRefusedError, InterruptedError):
            pass  # datagram links may drop; MAVLink protocols retry
        except OSError as exc:
            if exc.errno not in (errno.ENOBUFS, errno.EAGAIN, errno.ECONNREFUSED):
                raise

    @property
    def peers(self) -> int:
        return 1 if self.target is not None else len(self._peers)

    def close(self) -> None:
        self.sock.close()
