"""The real-time loop's deadlines: when the next control period is due, and the periods it
missed (pure: the times are given, no clock read here).

A period is missed when its step starts more than half a period after it was due; the
periods passed over entirely by a late step count as missed too, and the next one is due on
the original grid (PX4's and ArduPilot's fixed-rate loops keep their phase the same way).
The first `KEPT` misses are kept with when they happened and how late, for `--stats`: they
say which of the loop's own work (a mode's entry, a log rotation) made it late.
"""

from __future__ import annotations

KEPT = 1000


class Deadlines:
    """The loop's grid of periods (`period_s`) and its misses."""

    def __init__(self, period_s: float) -> None:
        self.period_s = period_s
        self.misses = 0
        self.first: list[tuple[float, float]] = []  # (s since boot, ms late)

    def step(self, now_s: float, due_s: float, boot_s: float) -> float:
        """A step starts at now_s for the period due at due_s (now_s >= due_s): the misses
        counted; when the next period is due."""
        late = now_s - due_s
        skipped = int(late // self.period_s)
        if late > 0.5 * self.period_s:
            self.misses += 1 + skipped
            if len(self.first) < KEPT:
                self.first.append((round(now_s - boot_s, 4), round(late * 1e3, 2)))
        return due_s + (skipped + 1) * self.period_s
