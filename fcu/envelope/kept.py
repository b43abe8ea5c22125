"""A bounded store for the planners' results (`fcu.envelope.feasibility.Envelope`): least recently
used out first, bounded both in entries and in the samples they hold; and arrays reused once
free (`Buffers`)."""

from __future__ import annotations

import sys
from collections import OrderedDict
from typing import Any

import numpy as np


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


class Buffers:
    """Large float arrays handed out again once nothing else holds them (`take`): a path's
    allocations are often dropped as soon as it is judged, and a large array mapped afresh
    costs the allocator's page faults, more than the product written into it."""

    def __init__(self, min_size: int, per_shape: int, max_shapes: int) -> None:
        self.min_size, self.per_shape, self.max_shapes = min_size, per_shape, max_shapes
        self._arrays: dict[tuple[int, int], list[np.ndarray]] = {}

    def take(self, rows: int, cols: int) -> np.ndarray:
        """An array of rows x cols (its values undefined) that no one else holds; below
        `min_size` values a new one."""
        if rows * cols < self.min_size:
            return np.empty((rows, cols))
        kept = self._arrays.get((rows, cols))
        if kept is None:
            if len(self._arrays) >= self.max_shapes:
                del self._arrays[next(iter(self._arrays))]
            kept = self._arrays[rows, cols] = []
        for a in kept:
            if sys.getrefcount(a) <= _FREE:  # held by the list, `a` and the argument alone
                return a
        out = np.empty((rows, cols))
        kept.append(out)
        if len(kept) > self.per_shape:
            del kept[0]
        return out

    def clear(self) -> None:
        self._arrays.clear()


_FREE = 3
