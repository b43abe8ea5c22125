"""How a run ends: the one divergence rule, the crash rule and the run status (DESIGN.md 6).

Used by the FCU's supervisor (divergence disarms), by the metrics (where the figures stop)
and by every runner (the status of a run), so that each question has one answer.

Statuses, exactly one per run:
    completed  the run reached its end with no failsafe reaction, divergence, crash, timeout
    failsafe   a failsafe reacted (HOLD, LAND or disarm), even one that later cleared
    diverged   position error beyond the limit or a state that is not finite
    crashed    a disarm in the air, or ground contact faster than CRASH_SPEED_M_S
    timeout    the run did not reach its end within its wall-clock allowance
    aborted    the run was stopped (interrupt, a process died, a refused step)
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import NamedTuple

import numpy as np

STATUSES = ("completed", "failsafe", "diverged", "crashed", "timeout", "aborted")
DIVERGENCE_M = 10.0  # default limit of the position error (COM_DIV_POS, scenario key)
CRASH_SPEED_M_S = 1.0  # touching the ground faster than this is a crash (LAND: 0.5 m/s)

# Event kinds: what a runner reads from the FCU's events besides their text.
INFO, FAILSAFE, CRASH, DIVERGED = "info", "failsafe", "crash", "diverged"
# How the FCU's STATUSTEXT begins when OFFBOARD holds its attitude instead of a target's
# (fcu/offboard.py); `gcs goto` ends on it with the vehicle's reason.
ATTITUDE_NOT_FLOWN = "attitude not flown"


class Event(NamedTuple):
    """Something the FCU said or did, on the flight clock (simulated time in lockstep)."""

    t_us: int
    severity: int  # MAV_SEVERITY
    text: str
    kind: str = INFO  # INFO, FAILSAFE (a reaction), CRASH (disarm in the air), DIVERGED

    def as_json(self) -> dict[str, object]:
        return {"t_s": self.t_us * 1e-6, "severity": self.severity, "text": self.text,
                "kind": self.kind}


def diverged(position_error_m: float, state_finite: bool, limit_m: float) -> bool:
    """The one divergence rule: a state that is not finite, or an error beyond the limit."""
    return not state_finite or not math.isfinite(position_error_m) or \
        position_error_m > limit_m


def diverged_rows(p: np.ndarray, q: np.ndarray, p_d: np.ndarray, q_d: np.ndarray,
                  limit_m: float) -> np.ndarray:
    """`diverged` for rows of truth (p, q) joined with desired (p_d, q_d)."""
    with np.errstate(invalid="ignore", over="ignore"):
        finite = np.all(np.isfinite(np.hstack([p, q, p_d, q_d])), axis=1)
        err = np.linalg.norm(p - p_d, axis=1)
        return np.asarray(~finite | ~np.isfinite(err) | (err > limit_m))


def touchdowns(landed: np.ndarray, speed_m_s: np.ndarray) -> list[tuple[int, float]]:
    """(row, speed just before contact) of every ground contact in a truth log: rows where
    `landed` turns true; the plant zeroes the velocity at contact, so the speed is the
    previous row's."""
    out = []
    for i in np.flatnonzero((landed[1:] > 0.5) & (landed[:-1] < 0.5)) + 1:
        out.append((int(i), float(speed_m_s[i - 1])))
    return out


class Outcome(NamedTuple):
    status: str
    failsafe: str  # the first failsafe reaction's text, "" when none
    reason: str  # one line on why the status is what it is


def classify(*, reached_end: bool, events: Iterable[Event], divergence_t_us: int | None,
             crash_t_us: int | None = None, stopped: str = "") -> Outcome:
    """The status of a run from what happened to the vehicle.

    `divergence_t_us`: first instant of divergence by `diverged` in the logs (None: never);
    the FCU's own divergence events count too (the earlier wins);
    `crash_t_us`: first ground contact faster than CRASH_SPEED_M_S (None: never);
    `stopped`: "timeout" or "aborted" when the runner could not finish the run.
    A disarm in the air caused by the divergence rule counts as divergence, not as a crash.
    """
    events = list(events)
    in_air = [e.t_us for e in events if e.kind == CRASH]
    flagged = [e.t_us for e in events if e.kind == DIVERGED]  # the FCU's own judgement
    divergence_t_us = min([t for t in (divergence_t_us, *flagged) if t is not None],
                          default=None)
    crash = min([t for t in (crash_t_us, *in_air) if t is not None], default=None)
    reactions = [e for e in events if e.kind == FAILSAFE]
    first = reactions[0].text if reactions else ""
    if divergence_t_us is not None and (crash is None or divergence_t_us <= crash):
        return Outcome("diverged", first, f"diverged at t = {divergence_t_us * 1e-6:.3f} s")
    if crash is not None:
        return Outcome("crashed", first, f"crashed at t = {crash * 1e-6:.3f} s")
    if stopped:
        return Outcome(stopped, first, stopped)
    if reactions:
        return Outcome("failsafe", first, f"failsafe at t = {reactions[0].t_us * 1e-6:.3f} s: "
                       f"{first}")
    if not reached_end:
        return Outcome("aborted", "", "the run ended before its end time")
    return Outcome("completed", "", "reached its end")
