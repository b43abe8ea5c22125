"""Free local ports for tests and `gcs run`, chosen so that the kernel does not hand them
out again."""

from __future__ import annotations

import random
import socket


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
