"""tcp: links, clients that connect and reconnect without ever blocking their caller."""

from __future__ import annotations

import errno
import os
import select
import socket
import time

from common.links.base import RECV_BATCH, Address, Link
from common.links.errors import LinkError, LinkUnavailable
from common.links.url import LinkUrl


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
        self.address: Address = (str(infos[0][4][0]), int(infos[0][4][1]))
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

    @property
    def unsent_bytes(self) -> int:
        """The end of the last write the socket did not take yet (sent before anything new)."""
        return len(self._tail)

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

    def _established(self, peer: Address) -> None:
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
