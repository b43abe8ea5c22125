"""Progress of a campaign on stderr: a bar with the ETA on a terminal, else a line per 10 %."""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from typing import Any


@dataclass
class Progress:
    """A progress bar with the ETA on a terminal; a line every 10 % otherwise."""

    total: int
    stream: Any = field(default_factory=lambda: sys.stderr)
    done: int = 0
    t0: float = field(default_factory=time.monotonic)
    statuses: dict[str, int] = field(default_factory=dict)
    _last_decile: int = -1

    def update(self, status: str) -> None:
        self.done += 1
        self.statuses[status] = self.statuses.get(status, 0) + 1
        elapsed = time.monotonic() - self.t0
        eta = elapsed / self.done * (self.total - self.done)
        counts = "  ".join(f"{k} {v}" for k, v in sorted(self.statuses.items()))
        if self.stream.isatty():
            width = 30
            fill = round(width * self.done / max(self.total, 1))
            self.stream.write(f"\r[{'#' * fill}{'.' * (width - fill)}] {self.done}/"
                              f"{self.total}  ETA {_clock(eta)}  {counts}\x1b[K")
            if self.done == self.total:
                self.stream.write("\n")
            self.stream.flush()
            return
        decile = 10 * self.done // max(self.total, 1)
        if decile != self._last_decile or self.done == self.total:
            self._last_decile = decile
            self.stream.write(f"campaign: {self.done}/{self.total} runs, {_clock(elapsed)} "
                              f"elapsed, ETA {_clock(eta)}  ({counts})\n")
            self.stream.flush()


def _clock(s: float) -> str:
    s = max(0, round(s))
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}" if s >= 3600 else \
        f"{s // 60}:{s % 60:02d}"

