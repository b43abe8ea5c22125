"""How long the ground station waits for a vehicle's answer: one policy for the mission,
parameter and command protocols (docs/ground-station.md, "How long the station waits").

A vehicle that is busy is still alive: it keeps sending its HEARTBEAT and telemetry, or the
protocol's next message (MISSION_REQUEST_INT, COMMAND_ACK with MAV_RESULT_IN_PROGRESS),
while it checks a mission or stores a parameter. So a wait for an answer ends only

- on silence: no message at all from the vehicle's system for `silence_s` (SILENCE_S, three
  of its 1 Hz heartbeats), or
- at its ceiling: the answer has not come within `ceiling_s` of asking, however alive the
  vehicle is;

and while it lasts, the request is re-sent each `resend_s` without an answer, as the
protocol says (the mission protocol's 1500 ms and 250 ms, a command's with its
confirmation incremented). Re-sending is harmless: a repeated last MISSION_ITEM is answered
with the MISSION_ACK again (ArduPilot, PX4, this FCU), a repeated PARAM_SET sets the same
value, a repeated COMMAND_LONG carries an incremented confirmation and is answered from the
vehicle's record of the command (this FCU) or acted on again (PX4, ArduPilot: the same state
asked again; a takeoff's refused copy is judged by `gcs.autopilot.commands.takeoff`).

The error names the reason: "vehicle silent for 3.0 s" or "within the 30 s ceiling".
Wall-clock time is right here: the station faces links and people, not the flight.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import Any, TypeGuard

SILENCE_S = 3.0  # nothing at all heard from the vehicle for this long: it is gone


@dataclass(frozen=True)
class Budget:
    """How one kind of answer is waited for: re-sent each `resend_s` without it (inf: never),
    given up after `silence_s` without any message from the vehicle or `ceiling_s` in all."""

    resend_s: float
    ceiling_s: float
    silence_s: float = SILENCE_S

    def but(self, **changes: float | None) -> Budget:
        """This budget with the given fields replaced (None: kept)."""
        return replace(self, **{k: v for k, v in changes.items() if v is not None})


# The policy (a table in docs/ground-station.md). Resend intervals are the protocols':
# the mission protocol's 1500 ms per transaction step and 250 ms per item.
MISSION_STEP = Budget(resend_s=1.5, ceiling_s=30.0)  # MISSION_COUNT, _REQUEST_LIST, _CLEAR_ALL
MISSION_ITEM = Budget(resend_s=0.25, ceiling_s=30.0)  # an item, and the ACK after the last
PARAM = Budget(resend_s=0.7, ceiling_s=10.0)  # PARAM_REQUEST_READ, PARAM_SET: its PARAM_VALUE
PARAM_LIST = Budget(resend_s=1.0, ceiling_s=10.0)  # ceiling: without a new parameter
COMMAND = Budget(resend_s=1.0, ceiling_s=10.0)  # COMMAND_LONG: its final COMMAND_ACK
MODE = Budget(resend_s=math.inf, ceiling_s=10.0)  # a HEARTBEAT showing the mode asked for


def from_target(msg: Any | None, system: int, component: int) -> TypeGuard[Any]:
    """Whether `msg` is a message of the target: vehicle `system`'s `component` (its
    autopilot; 0: any component). Another component of the system (a companion computer,
    a gimbal, a camera) sends its own HEARTBEAT, ATTITUDE or PARAM_VALUE, which say nothing
    of the autopilot's mode, state, parameters or answers."""
    return msg is not None and msg.get_type() != "BAD_DATA" and \
        msg.get_srcSystem() == system and \
        (not component or msg.get_srcComponent() == component)


class Wait:
    """One awaited answer under a `Budget`: when it was asked, sent, and the vehicle last
    heard (monotonic s). `heard()` at each message of the vehicle; `left()` is how long a
    receive may block; `due()` says when to re-send (then `sent()`); `expired()` the
    reason to give up, or ""."""

    def __init__(self, budget: Budget, now: float | None = None) -> None:
        t = time.monotonic() if now is None else now
        self.budget = budget
        self.start = self.last_heard = self.last_sent = t
        self.tries = 1
        self.resending = not math.isinf(budget.resend_s)  # False: only wait from now on

    def heard(self, now: float | None = None) -> None:
        self.last_heard = time.monotonic() if now is None else now

    def progressed(self, now: float | None = None) -> None:
        """The answer is coming (a new parameter of a list, a command's IN_PROGRESS): the
        ceiling counts from now."""
        self.start = time.monotonic() if now is None else now

    def note_session(self, session: Any) -> None:
        """Take the session's `last_heard` (any message of the vehicle, whoever read it)."""
        heard = getattr(session, "last_heard", 0.0)
        if heard > self.last_heard:
            self.heard(heard)

    def sent(self, now: float | None = None) -> None:
        self.last_sent = time.monotonic() if now is None else now
        self.tries += 1

    def stop_resending(self) -> None:
        """No more re-sends (the vehicle said it is working on it): wait, that is all."""
        self.resending = False

    def due(self, now: float | None = None) -> bool:
        t = time.monotonic() if now is None else now
        return self.resending and t - self.last_sent >= self.budget.resend_s

    def left(self, now: float | None = None) -> float:
        """Seconds until the next thing to do (re-send, or give up), at least 1 ms."""
        t = time.monotonic() if now is None else now
        b = self.budget
        ends = (self.last_sent + b.resend_s if self.resending else math.inf,
                self.last_heard + b.silence_s, self.start + b.ceiling_s)
        return max(0.001, min(ends) - t)

    def expired(self, now: float | None = None) -> str:
        """": vehicle silent for 3.0 s", " within the 30 s ceiling", or "" (keep waiting)."""
        t = time.monotonic() if now is None else now
        b = self.budget
        if t - self.last_heard >= b.silence_s:
            return f": vehicle silent for {b.silence_s:.1f} s"
        if t - self.start >= b.ceiling_s:
            return f" within the {b.ceiling_s:g} s ceiling"
        return ""

    def tries_text(self) -> str:
        """e.g. " (12 tries, 250 ms apart)"; "" for a wait that sends once."""
        if math.isinf(self.budget.resend_s):
            return ""
        return f" ({self.tries} {'try' if self.tries == 1 else 'tries'}, " \
            f"{self.budget.resend_s * 1e3:.0f} ms apart)"
