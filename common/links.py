"""Link URLs and the byte transports behind them (DESIGN.md section 1).

    udpin:HOST:PORT    bind and answer every peer heard in the last `peer_timeout_s` (at
                       most `max_peers` of them: a flood from many ports cannot make every
                       send a burst of thousands)
    udpout:HOST:PORT   send to HOST:PORT; only its replies are read (datagrams from any
                       other address are dropped and counted in `foreign_datagrams`)
    tcp:HOST:PORT      connect to a TCP server (reconnects when the server goes away)
    tcpin:HOST:PORT    listen for TCP clients and serve all of them
    serial:DEVICE:BAUD a serial port in raw mode

Every link is non-blocking: `recv()` returns the datagrams or stream chunks that are ready,
`send(data)` never waits, and `fileno()` lets one `select` serve all links. Peers are told
apart by `peer` keys so that each byte stream gets its own MAVLink parser. Zenoh links
(`zenoh:PREFIX[@ENDPOINT,...]`) live in `common/zenoh_link.py`.
"""

from __future__ import annotations

import errno
import ipaddress
import os
import socket
import time
from dataclasses import dataclass

SCHEMES = ("udpin", "udpout", "tcp", "tcpin", "serial", "zenoh")
# At most this many datagrams (or stream chunks) per recv(): under a flood the socket never
# runs dry, and a caller that reads until it does would never get back to its own work
# (the FCU's control step). What is left is read on the next call; select() says so.
RECV_BATCH = 256


class LinkError(ValueError):
    """A link URL that cannot be parsed or opened."""


@dataclass(frozen=True)
class LinkUrl:
    scheme: str
    host: str = ""
    port: int = 0
    device: str = ""
    baud: int = 0
    text: str = ""

    def __str__(self) -> str:
        return self.text


def parse_url(text: str) -> LinkUrl:
    """Parse a link URL; raises LinkError naming what is wrong."""
    scheme, sep, rest = text.partition(":")
    if not sep or scheme not in SCHEMES:
        raise LinkError(f"link '{text}': expected one of {', '.join(s + ':' for s in SCHEMES)}")
    if scheme == "zenoh":
        return LinkUrl(scheme, device=rest or "mavlink", text=text)
    if scheme == "serial":
        device, _, baud = rest.rpartition(":")
        if not device or not baud.isdigit():
            raise LinkError(f"link '{text}': expected serial:DEVICE:BAUD")
        return LinkUrl(scheme, device=device, baud=int(baud), text=text)
    host, _, port = rest.rpartition(":")
    if not host or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise LinkError(f"link '{text}': expected {scheme}:HOST:PORT with PORT in 0..65535")
    return LinkUrl(scheme, host=host, port=int(port), text=text)


class Link:
    """A non-blocking byte transport."""

    url: LinkUrl

    def fileno(self) -> int:
        raise NotImplementedError

    def filenos(self) -> list[int]:
        """Every descriptor to wait on (a TCP server also waits on its clients)."""
        fd = self.fileno()
        return [fd] if fd >= 0 else []

    # Worth polling without sleeping when an answer is microseconds away (sockets); a link
    # fed by another thread (Zenoh) must let that thread take the GIL instead.
    spin = True

    @property
    def is_stream(self) -> bool:
        return self.url.scheme in ("tcp", "tcpin", "serial")

    def recv(self) -> list[tuple[object, bytes]]:
        """Ready (peer, bytes) pairs; empty when nothing is waiting."""
        raise NotImplementedError

    def send(self, data: bytes) -> None:
        raise NotImplementedError

    def close(self) -> None:
        raise NotImplementedError

    @property
    def peers(self) -> int:
        return 1


def _resolve(url: LinkUrl) -> tuple[str, int]:
    """HOST:PORT as the IPv4 address datagrams come from; LinkError if HOST is unknown."""
    try:
        infos = socket.getaddrinfo(url.host, url.port, socket.AF_INET, socket.SOCK_DGRAM)
    except (socket.gaierror, UnicodeError) as exc:
        raise LinkError(f"link '{url}': cannot resolve {url.host}: {exc}") from None
    host, port = infos[0][4][:2]
    return host, port


def _is_unicast(host: str) -> bool:
    addr = ipaddress.IPv4Address(host)
    return not (addr.is_multicast or addr.is_unspecified or addr == _BROADCAST)


_BROADCAST = ipaddress.IPv4Address("255.255.255.255")


class UdpLink(Link):
    """udpin (bind, answer recent peers) or udpout (send to one address, read its replies)."""

    def __init__(self, url: LinkUrl, peer_timeout_s: float = 5.0, max_peers: int = 32) -> None:
        self.url = url
        self.peer_timeout_s = peer_timeout_s
        self.max_peers = max_peers
        self._peers: dict[tuple[str, int], float] = {}
        self.foreign_datagrams = 0  # udpout: datagrams from others than the target, dropped
        self.unanswered_peers = 0  # udpin: new peers not answered because the table was full
        target = _resolve(url) if url.scheme == "udpout" else None
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        try:
            if url.scheme == "udpin":
                self.sock.bind((url.host, url.port))
                self.target: tuple[str, int] | None = None
            else:
                self.sock.bind(("127.0.0.1" if url.host.startswith("127.") else "", 0))
                self.target = target
        except OSError as exc:
            self.sock.close()
            raise LinkError(f"link '{url}': {exc.strerror}") from None
        # Replies come from the address we send to, unless that is a group or broadcast.
        self._only = target if target is not None and _is_unicast(target[0]) else None
        self.sock.setblocking(False)

    @property
    def local_port(self) -> int:
        return self.sock.getsockname()[1]

    def fileno(self) -> int:
        return self.sock.fileno()

    def recv(self) -> list[tuple[object, bytes]]:
        out: list[tuple[object, bytes]] = []
        now = time.monotonic()
        for _ in range(RECV_BATCH):
            try:
                data, addr = self.sock.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                return out
            except ConnectionRefusedError:
                continue  # ICMP from a peer that went away: nothing to read
            if self.target is None:
                self._heard(addr, now)
            elif self._only is not None and addr[:2] != self._only:
                self.foreign_datagrams += 1  # not our peer's: nobody else talks on this link
                continue
            out.append((addr, data))
        return out

    def _heard(self, addr: tuple[str, int], now: float) -> None:
        peers = self._peers
        if addr in peers or len(peers) < self.max_peers:
            peers[addr] = now
            return
        self._expire(now)
        if len(peers) < self.max_peers:
            peers[addr] = now
        else:
            self.unanswered_peers += 1

    def _expire(self, now: float) -> None:
        stale = [a for a, t in self._peers.items() if now - t > self.peer_timeout_s]
        for addr in stale:
            del self._peers[addr]

    def send(self, data: bytes) -> None:
        if self.target is not None:
            self._sendto(data, self.target)
            return
        self._expire(time.monotonic())
        for addr in self._peers:
            self._sendto(data, addr)

    def _sendto(self, data: bytes, addr: tuple[str, int]) -> None:
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


class TcpClientLink(Link):
    """tcp:HOST:PORT, reconnecting (at most once per second) when the server goes away."""

    def __init__(self, url: LinkUrl) -> None:
        self.url = url
        self.sock: socket.socket | None = None
        self._next_try = 0.0
        self._connect()

    def _connect(self) -> None:
        now = time.monotonic()
        if self.sock is not None or now < self._next_try:
            return
        self._next_try = now + 1.0
        s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        try:
            s.settimeout(1.0)
            s.connect((self.url.host, self.url.port))
        except OSError:
            s.close()
            return
        s.setblocking(False)
        self.sock = s

    def fileno(self) -> int:
        self._connect()
        return self.sock.fileno() if self.sock is not None else -1

    def recv(self) -> list[tuple[object, bytes]]:
        if self.sock is None:
            self._connect()
            return []
        out: list[tuple[object, bytes]] = []
        for _ in range(RECV_BATCH):
            try:
                data = self.sock.recv(65536)
            except (BlockingIOError, InterruptedError):
                return out
            except OSError:
                data = b""
            if not data:
                self.sock.close()
                self.sock = None
                return out
            out.append((self.url.text, data))
        return out

    def send(self, data: bytes) -> None:
        if self.sock is None:
            self._connect()
            if self.sock is None:
                return
        try:
            self.sock.sendall(data)
        except (BlockingIOError, InterruptedError):
            pass
        except OSError:
            self.sock.close()
            self.sock = None

    def close(self) -> None:
        if self.sock is not None:
            self.sock.close()


class TcpServerLink(Link):
    """tcpin:HOST:PORT: accepts clients (up to `max_clients`) and serves all of them."""

    def __init__(self, url: LinkUrl, max_clients: int = 32) -> None:
        self.url = url
        self.server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self.server.bind((url.host, url.port))
        except OSError as exc:
            self.server.close()
            raise LinkError(f"link '{url}': {exc.strerror}") from None
        self.server.listen(8)
        self.server.setblocking(False)
        self.clients: dict[int, socket.socket] = {}
        self.max_clients = max_clients
        self.refused_clients = 0

    @property
    def local_port(self) -> int:
        return self.server.getsockname()[1]

    def fileno(self) -> int:
        return self.server.fileno()

    def filenos(self) -> list[int]:
        return [self.server.fileno(), *self.clients]

    def recv(self) -> list[tuple[object, bytes]]:
        for _ in range(RECV_BATCH):
            try:
                conn, _ = self.server.accept()
            except (BlockingIOError, InterruptedError):
                break
            except OSError:  # e.g. out of descriptors: the client waits in the backlog
                break
            if len(self.clients) >= self.max_clients:
                conn.close()  # a flood of connections must not take every descriptor
                self.refused_clients += 1
                continue
            conn.setblocking(False)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self.clients[conn.fileno()] = conn
        out: list[tuple[object, bytes]] = []
        for fd, conn in list(self.clients.items()):
            for _ in range(RECV_BATCH):
                try:
                    data = conn.recv(65536)
                except (BlockingIOError, InterruptedError):
                    break
                except OSError:
                    data = b""
                if not data:
                    conn.close()
                    del self.clients[fd]
                    break
                out.append((fd, data))
        return out

    def send(self, data: bytes) -> None:
        for fd, conn in list(self.clients.items()):
            try:
                conn.sendall(data)
            except (BlockingIOError, InterruptedError):
                pass
            except OSError:
                conn.close()
                del self.clients[fd]

    @property
    def peers(self) -> int:
        return len(self.clients)

    def close(self) -> None:
        for conn in self.clients.values():
            conn.close()
        self.server.close()


class SerialLink(Link):
    """serial:DEVICE:BAUD in raw mode (8N1, no flow control)."""

    def __init__(self, url: LinkUrl) -> None:
        import termios
        import tty

        self.url = url
        try:
            self.fd = os.open(url.device, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        except OSError as exc:
            raise LinkError(f"link '{url}': {exc.strerror}") from None
        speed = getattr(termios, f"B{url.baud}", None)
        if speed is None:
            os.close(self.fd)
            raise LinkError(f"link '{url}': unsupported baud rate {url.baud}")
        if os.isatty(self.fd):
            tty.setraw(self.fd)
            attrs = termios.tcgetattr(self.fd)
            attrs[4] = attrs[5] = speed
            termios.tcsetattr(self.fd, termios.TCSANOW, attrs)

    def fileno(self) -> int:
        return self.fd

    def recv(self) -> list[tuple[object, bytes]]:
        out: list[tuple[object, bytes]] = []
        for _ in range(RECV_BATCH):
            try:
                data = os.read(self.fd, 4096)
            except (BlockingIOError, InterruptedError):
                return out
            if not data:
                return out
            out.append((self.url.device, data))
        return out

    def send(self, data: bytes) -> None:
        try:
            os.write(self.fd, data)
        except (BlockingIOError, InterruptedError):
            pass

    def close(self) -> None:
        os.close(self.fd)


def open_link(url: str | LinkUrl, *, role: str = "vehicle", system_id: int = 0) -> Link:
    """Open a link from its URL; `role` and `system_id` choose a Zenoh link's keys."""
    parsed = url if isinstance(url, LinkUrl) else parse_url(url)
    if parsed.scheme == "zenoh":
        from common.zenoh_link import ZenohLink  # imported only where Zenoh is used

        return ZenohLink(parsed, role=role, system_id=system_id)
    if parsed.scheme in ("udpin", "udpout"):
        return UdpLink(parsed)
    if parsed.scheme == "tcp":
        return TcpClientLink(parsed)
    if parsed.scheme == "tcpin":
        return TcpServerLink(parsed)
    if parsed.scheme == "serial":
        return SerialLink(parsed)
    raise LinkError(f"link '{parsed}': unknown scheme")


def free_port(kind: int = socket.SOCK_DGRAM) -> int:
    """A port that is free on 127.0.0.1 now (for tests and `gcs run`)."""
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]
