"""Link URLs and the byte transports behind them (DESIGN.md section 1).

    udpin:HOST:PORT    bind and answer every peer heard in the last `peer_timeout_s` (at
                       most `max_peers` of them: a flood from many ports cannot make every
                       send a burst of thousands)
    udpout:HOST:PORT   send to HOST:PORT; only its replies are read (datagrams from any
                       other address are dropped and counted in `foreign_datagrams`)
    tcp:HOST:PORT      connect to a TCP server without blocking: an attempt in progress is
                       checked on every call, never waited for; attempts at most once per
                       second, each abandoned after a second without an answer; reconnects
                       when the server goes away; data sent while not connected is dropped
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
import random
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
    return str(host), int(port)


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
    """tcp:HOST:PORT, connecting and reconnecting without ever blocking the caller.

    HOST is resolved once, when the link is opened (no name lookups in the caller's loop).
    An attempt is a non-blocking `connect`; while it is in progress (`connecting`) every call
    of `fileno()`, `filenos()`, `recv()` and `send()` checks it with `SO_ERROR` (set once the
    attempt has failed) and `getpeername()` (ENOTCONN until the handshake is done): two
    system calls that never wait, without the FD_SETSIZE limit of a `select`. `filenos()`
    includes the socket while it connects: a refused or failed attempt is readable, so the
    caller's read-`select` wakes for it at once; a completed one is not readable and is
    noticed at the caller's next call of any of these (the FCU rebuilds its descriptor list
    every turn of its loop, at least every 50 ms). An attempt still pending after
    `connect_timeout_s` is abandoned (an address that drops SYNs), attempts start at most
    once every `retry_s`, and a connection closed, reset or refused by the server is noticed
    by `recv()` (end of stream) or `send()` (broken pipe) and retried the same way. A
    connection to itself (possible when nothing listens on a local ephemeral port) is dropped.

    `send()` never waits: while not connected it drops the data (like a datagram link); when
    the socket buffer is full it keeps the unsent tail of the last write, so that the peer
    never sees half a frame followed by another, and drops whole writes until that tail has
    gone out. Dropped writes are counted in `dropped_sends`, connections made in `connects`.
    """

    def __init__(
        self, url: LinkUrl, *, retry_s: float = 1.0, connect_timeout_s: float = 1.0
    ) -> None:
        self.url = url
        self.retry_s = retry_s
        self.connect_timeout_s = connect_timeout_s
        try:
            infos = socket.getaddrinfo(url.host, url.port, socket.AF_INET, socket.SOCK_STREAM)
        except (socket.gaierror, UnicodeError) as exc:
            raise LinkError(f"link '{url}': cannot resolve {url.host}: {exc}") from None
        self.address: tuple[str, int] = (str(infos[0][4][0]), int(infos[0][4][1]))
        self.sock: socket.socket | None = None
        self.connecting = False  # self.sock is an attempt in progress, not a connection
        self._started = 0.0  # when the current attempt began
        self._next_try = 0.0  # no attempt starts before this (monotonic seconds)
        self._tail = b""  # unsent end of the last write, sent before anything new
        self.connects = 0  # connections made (a reconnection counts again)
        self.dropped_sends = 0
        self._poll()

    @property
    def connected(self) -> bool:
        return self.sock is not None and not self.connecting

    def _poll(self) -> None:
        """Start an attempt if one is due, or see whether the one in progress is done."""
        if self.sock is None:
            now = time.monotonic()
            if now >= self._next_try:
                self._start(now)
            return
        if not self.connecting:
            return
        s = self.sock
        if s.getsockopt(socket.SOL_SOCKET, socket.SO_ERROR):
            self._drop()  # refused, unreachable, timed out: the next attempt is due later
            return
        try:
            peer = s.getpeername()  # ENOTCONN until the handshake is done
        except OSError:
            if time.monotonic() - self._started >= self.connect_timeout_s:
                self._drop()  # no answer (SYNs dropped): abandon, a new attempt follows
            return
        self._established(peer)

    def _established(self, peer: tuple[str, int]) -> None:
        assert self.sock is not None
        if peer == self.sock.getsockname():
            # Connected to itself: with nothing listening on a local port of the ephemeral
            # range, a connect can pick that very port as its source (TCP simultaneous open)
            # and would then read back everything it sends.
            self._drop()
            return
        self.connecting = False
        self.connects += 1

    def _start(self, now: float) -> None:
        self._next_try = now + self.retry_s
        self._started = now
        try:
            s = self._new_socket()
        except OSError:
            return  # e.g. out of descriptors: try again later
        err = s.connect_ex(self.address)
        if err == 0:
            self.sock, self.connecting = s, True
            try:
                self._established(s.getpeername())
            except OSError:
                self._drop()
        elif err in (errno.EINPROGRESS, errno.EWOULDBLOCK, errno.EALREADY, errno.EINTR):
            self.sock, self.connecting = s, True
        else:
            s.close()  # refused at once (or no route): wait for the next attempt

    def _new_socket(self) -> socket.socket:
        s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        try:
            s.setblocking(False)
            s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        except OSError:
            s.close()
            raise
        return s

    def _drop(self) -> None:
        if self.sock is not None:
            self.sock.close()
        self.sock = None
        self.connecting = False
        self._tail = b""

    def fileno(self) -> int:
        self._poll()
        return self.sock.fileno() if self.sock is not None else -1

    def recv(self) -> list[tuple[object, bytes]]:
        self._poll()
        if not self.connected:
            return []
        out: list[tuple[object, bytes]] = []
        assert self.sock is not None  # connected
        for _ in range(RECV_BATCH):
            try:
                data = self.sock.recv(65536)
            except (BlockingIOError, InterruptedError):
                return out
            except OSError:
                data = b""  # reset
            if not data:
                self._drop()
                return out
            out.append((self.url.text, data))
        return out

    def send(self, data: bytes) -> None:
        self._poll()
        if not self.connected:
            self.dropped_sends += 1
            return
        assert self.sock is not None  # connected
        try:
            if self._tail:
                sent = self.sock.send(self._tail)
                self._tail = self._tail[sent:]
                if self._tail:
                    self.dropped_sends += 1
                    return
            sent = self.sock.send(data)
            self._tail = data[sent:]
        except (BlockingIOError, InterruptedError):
            self.dropped_sends += 1
        except OSError:
            self.dropped_sends += 1
            self._drop()  # reset or broken pipe: the next attempt is at most retry_s away

    def close(self) -> None:
        self._drop()
        self._next_try = float("inf")


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


def _ephemeral_range() -> tuple[int, int]:
    try:
        with open("/proc/sys/net/ipv4/ip_local_port_range") as fh:
            lo, hi = (int(x) for x in fh.read().split())
        return lo, hi
    except (OSError, ValueError):
        return 32768, 60999  # Linux's default


def free_port(kind: int = socket.SOCK_DGRAM) -> int:
    """A port that is free on 127.0.0.1 now (for tests and `gcs run`).

    Chosen at random below the kernel's ephemeral range: a port the kernel handed out for
    `bind(0)` is soon handed out again to any process binding port 0 (every udpout link
    does), which then steals it from whoever was told it was free.
    """
    lo, _ = _ephemeral_range()
    top = lo - 1 if lo > 12000 else 65535
    rng = random.SystemRandom()
    for _ in range(200):
        port = rng.randint(10000, top)
        with socket.socket(socket.AF_INET, kind) as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                continue
            return port
    with socket.socket(socket.AF_INET, kind) as s:  # a crowded machine: the kernel's choice
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])
