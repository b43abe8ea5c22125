"""The udpin peer table: a guard against hostile senders. Every peer heard in the last
`timeout_s` is answered, at most `max_peers` of them, the first ones kept: a flood from many
ports can neither grow the table nor make every send a burst of thousands."""

from __future__ import annotations

from common.links.base import Address


class PeerTable:
    """Recently heard peers (address -> monotonic time last heard), bounded."""

    def __init__(self, timeout_s: float = 5.0, max_peers: int = 32) -> None:
        self.timeout_s = timeout_s
        self.max_peers = max_peers
        self.heard: dict[Address, float] = {}
        self.unanswered = 0  # new peers not answered because the table was full

    def add(self, addr: Address, now: float) -> None:
        """A datagram from `addr` at `now`: kept, unless the table is full of live peers."""
        heard = self.heard
        if addr in heard or len(heard) < self.max_peers:
            heard[addr] = now
            return
        self.expire(now)
        if len(heard) < self.max_peers:
            heard[addr] = now
        else:
            self.unanswered += 1

    def expire(self, now: float) -> None:
        """Forget the peers not heard for more than `timeout_s`."""
        stale = [a for a, t in self.heard.items() if now - t > self.timeout_s]
        for addr in stale:
            del self.heard[addr]

    def __len__(self) -> int:
        return len(self.heard)
