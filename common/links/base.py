"""What every link is: a non-blocking byte transport (`Link`), its batch bound, and the one
line for a bind that failed."""

from __future__ import annotations

import errno
import socket

from common.links.errors import LinkError
from common.links.url import LinkUrl

# At most this many datagrams (or stream chunks) per recv(): under a flood the socket never
# runs dry, and a caller that reads until it does would never get back to its own work
# (the FCU's control step). What is left is read on the next call; select() says so.
RECV_BATCH = 256
Address = tuple[str, int]  # an IPv4 address and port, as sockets give and take them


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


def bind_error(url: LinkUrl, exc: OSError) -> LinkError:
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


def first_line(exc: BaseException) -> str:
    """The first line of an exception's message (its type's name if it has none)."""
    return (str(exc).splitlines() or [type(exc).__name__])[0]
