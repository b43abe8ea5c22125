"""What the commander says: events stamped on the flight clock at the latest input; the
process shell turns them into STATUSTEXT."""

from __future__ import annotations

from common.outcome import INFO, Event


class Voice:
    """The flight clock at the latest input, and the events said at it."""

    def __init__(self) -> None:
        self.clock_us = 0
        self.events: list[Event] = []

    def say(self, severity: int, text: str, kind: str = INFO) -> None:
        self.events.append(Event(self.clock_us, severity, text[:50], kind))
