"""tcpin: links, a TCP server that serves every client (at most `max_clients` of them)."""

from __future__ import annotations

import socket

from common.links.base import RECV_BATCH, Link, bind_error
from common.links.url import LinkUrl


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
            raise bind_error(url, exc) from None
        self.server.setblocking(False)
        self.clients: dict[int, socket.socket] = {}
        self.max_clients = max_clients
        self.refused_clients = 0

    @property
    def local_port(self) -> int:
        port: int = self.server.getsockname()[1]
        return port

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
