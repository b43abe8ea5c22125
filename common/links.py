"""Link URLs and the byte transports behind them (DESIGN.md section 1): the one link layer
of `fcu`, `sitl` and `gcs`.

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
    serial:DEVICE:BAUD a serial port (pyserial) in raw mode, 8N1, no flow control
    zenoh:PREFIX[@ENDPOINT,...]   Zenoh pub/sub (`common/zenoh_link.py`)

MAVSDK's and pymavlink's spellings are accepted too and mean the same links: `udpin://`,
`udpout://`, `udp://HOST:PORT` and `udp:HOST:PORT` (listen, as MAVSDK's old form and
pymavlink's), `tcp://` and `tcpout://` (client), `tcpin://`, `serial://DEVICE:BAUD`
(`serial:///dev/ttyUSB0:57600`). An empty HOST on a listening link (`udp://:14540`) means
every interface, as in MAVSDK; everywhere else HOST is required. PORT is 1..65535; 0 (any
free port, which the link's `local_port` then tells) only on a listening link (udpin, tcpin).

Errors are `LinkError`s with a one-line message: a URL that does not parse, a port out of
range, a device that does not exist, a port another process holds (never shared: no
SO_REUSEPORT, and UDP ports without SO_REUSEADDR) are bad input (`exit_code` 2); a peer that
is not there (`LinkUnavailable`: a refused TCP connect, for callers that wait for one; a Zenoh
router that cannot be reached) is a runtime failure (`exit_code` 1).

Every link is non-blocking: `recv()` returns the datagrams or stream chunks that are ready,
`send(data)` never waits, and `fileno()` lets one `select` serve all links. Peers are told
apart by `peer` keys so that each byte stream gets its own MAVLink parser.
"""

from __future__ import annotations

import errno
import ipaddress
import os
import random
import select
import socket
import time
from dataclasses import dataclass

SCHEMES = ("udpin", "udpout", "tcp", "tcpin", "serial", "zenoh")
# Other spellings (MAVSDK, pymavlink) -> the scheme they mean.
ALIASES = {"udp": "udpin", "tcpout": "tcp"}
LISTENING = ("udpin", "tcpin")
# At most this many datagrams (or stream chunks) per recv(): under a flood the socket never
# runs dry, and a caller that reads until it does would never get back to its own work
# (the FCU's control step). What is left is read on the next call; select() says so.
RECV_BATCH = 256
FORMS = ("udpin:HOST:PORT, udpout:HOST:PORT, tcp:HOST:PORT, tcpin:HOST:PORT, "
         "serial:DEVICE:BAUD, zenoh:PREFIX[@ENDPOINT] (or MAVSDK's udpin://, udpout://, "
         "udp://, tcp://, tcpin://, serial://)")


class LinkError(ValueError):
    """A link URL that cannot be parsed or opened: bad input, exit status 2."""

    exit_code = 2


class LinkUnavailable(LinkError):
    """The other end is not there (a refused TCP connect): a runtime failure, exit status 1."""

    exit_code = 1


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

    @property
    def canonical(self) -> str:
        """The URL in this project's own spelling (`udp://:14540` -> `udpin:0.0.0.0:14540`)."""
        if self.scheme == "zenoh":
            return f"zenoh:{self.device}"
        if self.scheme == "serial":
            return f"serial:{self.device}:{self.baud}"
        return f"{self.scheme}:{self.host}:{self.port}"


def parse_url(text: str) -> LinkUrl:
    """Parse a link URL (any spelling above); raises LinkError naming what is wrong.

    Only the text is checked here (no name lookups, no file system): opening the link
    checks that the host resolves, the port is free, the device exists."""
    given, sep, rest = text.partition(":")
    name = given.lower()
    scheme = ALIASES.get(name, name)
    if not sep or scheme not in SCHEMES:
        what = f"unknown link type '{given}'" if sep and given else "not a link URL"
        raise LinkError(f"link '{text}': {what}; expected {FORMS}")
    if rest.startswith("//"):
        rest = rest[2:]  # MAVSDK's scheme://...; serial:///dev/x keeps its leading /
    if scheme == "zenoh":
        from common.zenoh_link import parse_zenoh  # imported only where Zenoh is used

        try:
            parse_zenoh(rest)
        except LinkError as exc:
            raise LinkError(f"link '{text}': {exc}") from None
        return LinkUrl(scheme, device=rest or "mavlink", text=text)
    if scheme == "serial":
        device, colon, baud = rest.rpartition(":")
        if not colon or not device or not baud.isdigit() or baud.startswith("0"):
            raise LinkError(f"link '{text}': expected serial:DEVICE:BAUD, e.g. "
                            "serial:/dev/ttyUSB0:57600")
        if not 50 <= int(baud) <= 20_000_000:
            raise LinkError(f"link '{text}': baud rate {baud} out of range (50..20000000)")
        return LinkUrl(scheme, device=device, baud=int(baud), text=text)
    host, colon, port = rest.rpartition(":")
    if not colon or not port:
        raise LinkError(f"link '{text}': no port; expected {given}:HOST:PORT")
    if not port.isascii() or not port.isdigit():
        raise LinkError(f"link '{text}': port '{port}' is not a number")
    number = int(port)
    listening = scheme in LISTENING
    if not 1 <= number <= 65535 and not (number == 0 and listening):
        allowed = "1..65535, or 0 for any free port" if listening else "1..65535"
        raise LinkError(f"link '{text}': port {port} out of range ({allowed})")
    if host.startswith("[") or ":" in host:
        raise LinkError(f"link '{text}': IPv6 addresses are not supported; use an IPv4 "
                        "address or a host name")
    if not host:
        if not listening:
            raise LinkError(f"link '{text}': no host; expected {given}:HOST:PORT")
        host = "0.0.0.0"  # MAVSDK's udp://:14540: every interface
    if any(c.isspace() or c in "/@?#" for c in host):
        raise LinkError(f"link '{text}': '{host}' is not a host name or IPv4 address")
    return LinkUrl(scheme, host=host, port=number, text=text)


def _bind_error(url: LinkUrl, exc: OSError) -> LinkError:
    """One line for a bind or listen that failed."""
    where = f"{url.host}:{url.port}"
    if isinstance(exc, socket.gaierror):
        return LinkError(f"link '{url}': cannot resolve {url.host}: {exc.strerror}")
    if exc.errno == errno.EADDRINUSE:
        return LinkError(f"link '{url}': {where} is in use by another process")
    if exc.errno == errno.EACCES:
        return LinkError(f"link '{url}': no permission to use {where} (ports below 1024 "
                         "need privileges)")
    if exc.errno == errno.EADDRNOTAVAIL:
        return LinkError(f"link '{url}': {url.host} is not an address of this machine")
    return LinkError(f"link '{url}': {exc.strerror or exc}")


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

    def recv(self, limit: int = RECV_BATCH) -> list[tuple[object, bytes]]:
        """Ready (peer, bytes) pairs, at most `limit` of them; empty when nothing is waiting.
        (A caller that knows one is ready and wants no more asks for 1: a datagram socket
        then does not try again only to be told that nothing is left.)"""
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
        # Never SO_REUSEADDR or SO_REUSEPORT: on Linux either lets a second process bind a
        # udpin port and silently take half of its datagrams (pymavlink sets SO_REUSEADDR);
        # here the second one is told the port is in use.
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
            raise _bind_error(url, exc) from None
        # Replies come from the address we send to, unless that is a group or broadcast.
        self._only = target if target is not None and _is_unicast(target[0]) else None
        self.sock.setblocking(False)

    @property
    def local_port(self) -> int:
        return self.sock.getsockname()[1]

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

    def send_to(self, data: bytes, peer: object) -> None:
        """Send to one peer that `recv` returned (an answer to its sender only)."""
        self._sendto(data, peer)  # type: ignore[arg-type]

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
        self.last_error = 0  # errno of the last attempt that failed (0: none yet, or connected)
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
        err = s.getsockopt(socket.SOL_SOCKET, socket.SO_ERROR)
        if err:
            self.last_error = err
            self._drop()  # refused, unreachable, timed out: the next attempt is due later
            return
        try:
            peer = s.getpeername()  # ENOTCONN until the handshake is done
        except OSError:
            if time.monotonic() - self._started >= self.connect_timeout_s:
                self.last_error = errno.ETIMEDOUT
                self._drop()  # no answer (SYNs dropped): abandon, a new attempt follows
            return
        self._established(peer)

    def _established(self, peer: tuple[str, int]) -> None:
        assert self.sock is not None
        if peer == self.sock.getsockname():
            # Connected to itself: with nothing listening on a local port of the ephemeral
            # range, a connect can pick that very port as its source (TCP simultaneous open)
            # and would then read back everything it sends.
            self.last_error = errno.ECONNREFUSED
            self._drop()
            return
        self.connecting = False
        self.connects += 1
        self.last_error = 0

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
            self.last_error = err
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

    def wait_connected(self, timeout_s: float) -> None:
        """Block until connected (for a caller with nothing to do before, e.g. `gcs`);
        LinkUnavailable at the first failed attempt (refused, unreachable) or after
        `timeout_s`. Reconnection later stays automatic."""
        deadline = time.monotonic() + timeout_s
        while True:
            self._poll()
            if self.connected:
                return
            if self.sock is None and self.last_error:
                break
            left = deadline - time.monotonic()
            if left <= 0:
                self.last_error = self.last_error or errno.ETIMEDOUT
                break
            if self.sock is not None:
                select.select([self.sock], [self.sock], [], min(left, 0.05))
            else:
                time.sleep(min(left, 0.05))
        why = os.strerror(self.last_error).lower()
        if self.last_error == errno.ECONNREFUSED:
            why = "connection refused (nothing listens there)"
        raise LinkUnavailable(f"link '{self.url}': cannot connect to "
                              f"{self.address[0]}:{self.address[1]}: {why}")

    def recv(self, limit: int = RECV_BATCH) -> list[tuple[object, bytes]]:
        self._poll()
        if not self.connected:
            return []
        out: list[tuple[object, bytes]] = []
        assert self.sock is not None  # connected
        for _ in range(limit):
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
        # SO_REUSEADDR only lets a restarted server take its port back from connections in
        # TIME_WAIT; on Linux it never shares a port another socket listens on (that would
        # take SO_REUSEPORT, never set here).
        self.server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self.server.bind((url.host, url.port))
            self.server.listen(8)
        except OSError as exc:
            self.server.close()
            raise _bind_error(url, exc) from None
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

    def recv(self, limit: int = RECV_BATCH) -> list[tuple[object, bytes]]:
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
            for _ in range(limit):
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
    """serial:DEVICE:BAUD through pyserial: raw, 8N1, no flow control, never waiting.

    The device is opened exclusively (a second process is told it is in use, not given half
    the bytes). A device that goes away (a USB adapter pulled, the other end of a pty
    closed) is closed and reopened at most once per `retry_s`; meanwhile nothing is read and
    writes are dropped (counted in `dropped_sends`). A write the driver takes only in part
    keeps its unsent tail, sent before anything new, so that no frame is cut."""

    def __init__(self, url: LinkUrl, retry_s: float = 1.0) -> None:
        self.url = url
        self.retry_s = retry_s
        self._next_try = 0.0
        self._tail = b""
        self.dropped_sends = 0
        self.reopens = 0
        self.port = self._open()

    def _open(self):  # -> serial.Serial
        import stat

        serial = _pyserial()
        url, device = self.url, self.url.device
        try:
            mode = os.stat(device).st_mode
        except FileNotFoundError:
            raise LinkError(f"link '{url}': no such device {device}") from None
        except OSError as exc:
            raise LinkError(f"link '{url}': {device}: {exc.strerror}") from None
        if not stat.S_ISCHR(mode):
            raise LinkError(f"link '{url}': {device} is not a serial device")
        try:
            port = serial.Serial(device, url.baud, timeout=0, write_timeout=0, exclusive=True)
        except (serial.SerialException, OSError) as exc:
            code = getattr(exc, "errno", None)
            if code in (errno.EAGAIN, errno.EWOULDBLOCK, errno.EBUSY):
                why = f"{device} is in use by another process"
            elif code == errno.EACCES:
                why = f"no permission to open {device} (on Linux: the dialout group)"
            elif code == errno.ENOENT:
                why = f"no such device {device}"
            else:
                why = f"cannot open {device}: {_first_line(exc)}"
            raise LinkError(f"link '{url}': {why}") from None
        except ValueError as exc:  # a baud rate the driver refuses
            raise LinkError(f"link '{url}': {exc}") from None
        return port

    def _lost(self) -> None:
        if self.port is not None:
            try:
                self.port.close()
            except (OSError, ValueError):
                pass
        self.port = None
        self._tail = b""
        self._next_try = time.monotonic() + self.retry_s

    def _reopen(self) -> None:
        if self.port is None and time.monotonic() >= self._next_try:
            self._next_try = time.monotonic() + self.retry_s
            try:
                self.port = self._open()
                self.reopens += 1
            except LinkError:
                pass

    def fileno(self) -> int:
        self._reopen()
        return self.port.fileno() if self.port is not None else -1

    def recv(self, limit: int = RECV_BATCH) -> list[tuple[object, bytes]]:
        serial = _pyserial()
        self._reopen()
        out: list[tuple[object, bytes]] = []
        if self.port is None:
            return out
        for _ in range(limit):
            try:
                data = self.port.read(4096)
            except (serial.SerialException, OSError):
                self._lost()  # readable without data: the device has gone
                return out
            if not data:
                return out
            out.append((self.url.device, data))
        return out

    def send(self, data: bytes) -> None:
        serial = _pyserial()
        self._reopen()
        if self.port is None:
            self.dropped_sends += 1
            return
        try:
            if self._tail:
                self._tail = self._tail[self.port.write(self._tail) or 0:]
                if self._tail:
                    self.dropped_sends += 1
                    return
            self._tail = data[self.port.write(data) or 0:]
        except serial.SerialTimeoutException:
            self.dropped_sends += 1
        except (serial.SerialException, OSError):
            self.dropped_sends += 1
            self._lost()

    def close(self) -> None:
        if self.port is not None:
            self.port.close()
            self.port = None
        self._next_try = float("inf")


def _pyserial():
    """pyserial, imported where a serial link is used."""
    import serial  # type: ignore[import-untyped]

    return serial


def _first_line(exc: BaseException) -> str:
    return (str(exc).splitlines() or [type(exc).__name__])[0]


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
