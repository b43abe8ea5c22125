"""A lossy UDP proxy for tests: drops, duplicates, reorders and delays datagrams in both
directions with a seeded RNG, between a client (who sends to `port`) and a server."""

from __future__ import annotations

import heapq
import random
import select
import socket
import threading
import time
from dataclasses import dataclass


@dataclass
class Impairment:
    drop: float = 0.0
    duplicate: float = 0.0
    reorder: float = 0.0  # probability that a datagram is held back behind the next ones
    delay_s: float = 0.0


class UdpProxy:
    def __init__(self, server_port: int, impairment: Impairment, seed: int = 0) -> None:
        self.server = ("127.0.0.1", server_port)
        self.imp = impairment
        self.rng = random.Random(seed)
        self.front = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.front.bind(("127.0.0.1", 0))
        self.back = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.back.bind(("127.0.0.1", 0))
        self.port = self.front.getsockname()[1]
        self.client: tuple[str, int] | None = None
        self.counts = {"forwarded": 0, "dropped": 0, "duplicated": 0, "reordered": 0}
        self._queue: list[tuple[float, int, socket.socket, bytes, tuple[str, int]]] = []
        self._n = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="udp-proxy", daemon=True)
        self._thread.start()

    def _schedule(self, sock: socket.socket, data: bytes,
                  addr: tuple[str, int]) -> None:
        imp = self.imp
        if self.rng.random() < imp.drop:
            self.counts["dropped"] += 1
            return
        copies = 2 if self.rng.random() < imp.duplicate else 1
        self.counts["duplicated"] += copies - 1
        delay = imp.delay_s
        if self.rng.random() < imp.reorder:
            delay += 0.002
            self.counts["reordered"] += 1
        for _ in range(copies):
            self._n += 1
            heapq.heappush(self._queue, (time.monotonic() + delay, self._n, sock, data, addr))

    def _run(self) -> None:
        while not self._stop.is_set():
            timeout = 0.05
            if self._queue:
                timeout = max(0.0, min(timeout, self._queue[0][0] - time.monotonic()))
            readable, _, _ = select.select([self.front, self.back], [], [], timeout)
            for sock in readable:
                try:
                    data, addr = sock.recvfrom(65535)
                except OSError:
                    continue
                if sock is self.front:
                    self.client = addr
                    self._schedule(self.back, data, self.server)
                elif self.client is not None:
                    self._schedule(self.front, data, self.client)
            now = time.monotonic()
            while self._queue and self._queue[0][0] <= now:
                _, _, sock, data, addr = heapq.heappop(self._queue)
                try:
                    sock.sendto(data, addr)
                    self.counts["forwarded"] += 1
                except OSError:
                    pass

    def inject(self, data: bytes, *, to_server: bool = False) -> bool:
        """Send `data` as if it had come through the link (a corrupting wire, a man in the
        middle): to the client from the address it talks to, or to the server from the
        proxy's own. False while the client is not known yet."""
        try:
            if to_server:
                self.back.sendto(data, self.server)
            elif self.client is not None:
                self.front.sendto(data, self.client)
            else:
                return False
        except (BlockingIOError, ConnectionRefusedError):
            return False  # a full buffer drops it, as the link would
        return True

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self.front.close()
        self.back.close()
