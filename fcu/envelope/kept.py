"""A bounded store for the planners' results (`fcu.envelope.feasibility.Envelope`): least recently
used out first, bounded both in entries and in the samples they hold."""

from __future__ import annotations

from collections import OrderedDict
from typing import Any


class Kept:
    """A bounded store, the least recently used entry out first: at most `max_rows` rows
    (each entry counts the samples it holds) and `max_entries` entries."""

    def __init__(self, max_rows: int, max_entries: int) -> None:
        self.max_rows, self.max_entries = max_rows, max_entries
        self._entries: OrderedDict[bytes, tuple[Any, int]] = OrderedDict()
        self._rows = 0

    def get(self, key: bytes) -> Any:
        """The entry kept for key (now the most recently used), or None."""
        hit = self._entries.get(key)
        if hit is None:
            return None
        self._entries.move_to_end(key)
        return hit[0]

    def put(self, key: bytes, value: Any, rows: int) -> None:
        entries = self._entries
        entries[key] = value, rows
        self._rows += rows
        while len(entries) > 1 and (self._rows > self.max_rows or
                                    len(entries) > self.max_entries):
            _, (_, old_rows) = entries.popitem(last=False)
            self._rows -= old_rows

    def clear(self) -> None:
        self._entries.clear()
        self._rows = 0
