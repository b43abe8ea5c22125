"""How a run ends: the one divergence rule, the crash rule and the run status
(docs/autopilot.md#how-a-run-ends).

Used by the FCU's supervisor (divergence disarms), by the metrics (where the figures stop)
and by every runner (the status of a run), so that each question has one answer.

Divergence has two bounds. Position: the error |p - p_d| beyond the scenario's limit
(`divergence_position_m`, COM_DIV_POS; DIVERGENCE_M by default), judged at every sample, by
the FCU too (`diverged`: it disarms). Attitude: the error angle of q_d* q above
DIVERGENCE_ATTITUDE_RAD held for DIVERGENCE_ATTITUDE_HOLD_S without a break, judged on the
logs (`diverged_rows`, which the metrics of in-process and process runs alike use); a
momentary peak, such as Case II's impulse response (2.2 rad for under 0.6 s, the paper's
Table I: 2.14 rad), is flown through, an attitude that is not tracked at all (Case II's
sinusoidal disturbance: 1.43 rad on average, above 2 rad for 2.1 s at a time) is a
divergence. The FCU does not judge attitude: such a run flies on, armed, to its end.

Statuses, exactly one per run:
    completed  the run reached its end with no failsafe reaction, divergence, crash, timeout
               or actuator limit
    limited    the run reached its end, but the FCU's actuator monitor reported an actuator
               at its limit on the way (a tilt servo rate-limited, a rotor at its speed
               limit: events of kind LIMIT): the flight ended, not as planned
    failsafe   a failsafe reacted (HOLD, LAND or disarm), even one that later cleared
    diverged   position error beyond the limit, attitude error above its limit held for its
               hold time, or a state that is not finite
    crashed    a disarm in the air, or ground contact faster than CRASH_SPEED_M_S
    timeout    the run did not reach its end within its wall-clock allowance
    aborted    the run was stopped (interrupt, a process died, a refused step)

Precedence, first match wins: diverged or crashed (whichever came first), a stopped run
(timeout, aborted), failsafe, a run that ended before its end (aborted), limited, completed.
A limit reported on the way to a divergence, a crash or a failsafe is in the events, the
status is the graver one.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import NamedTuple

import numpy as np

from common.quaternion import angle_between_rows

STATUSES = ("completed", "limited", "failsafe", "diverged", "crashed", "timeout", "aborted")
DIVERGENCE_M = 10.0  # default limit of the position error (COM_DIV_POS, scenario key)
DIVERGENCE_ATTITUDE_RAD = 2.0  # attitude error angle limit (115 deg) ...
DIVERGENCE_ATTITUDE_HOLD_S = 1.0  # ... held this long without a break: a divergence
CRASH_SPEED_M_S = 1.0  # touching the ground faster than this is a crash (LAND: 0.5 m/s)

# Event kinds: what a runner reads from the FCU's events besides their text. LIMIT: the
# actuator monitor's report of an actuator at its limit (a WARNING, no reaction).
INFO, FAILSAFE, CRASH, DIVERGED, LIMIT = "info", "failsafe", "crash", "diverged", "limit"
# How the FCU's STATUSTEXT begins when OFFBOARD holds its attitude instead of a target's
# (fcu/modes/offboard.py); `gcs goto` ends on it with the vehicle's reason.
ATTITUDE_NOT_FLOWN = "attitude not flown"


class Event(NamedTuple):
    """Something the FCU said or did, on the flight clock (simulated time in lockstep)."""

    t_us: int
    severity: int  # MAV_SEVERITY
    text: str
    kind: str = INFO  # INFO, FAILSAFE (a reaction), CRASH (disarm in the air), DIVERGED,
    # LIMIT (an actuator at its limit, reported)

    def as_json(self) -> dict[str, object]:
        return {"t_s": self.t_us * 1e-6, "severity": self.severity, "text": self.text,
                "kind": self.kind}


def diverged(position_error_m: float, state_finite: bool, limit_m: float) -> bool:
    """The divergence rule at one step, the FCU's: a state that is not finite, or a position
    error beyond the limit (`diverged_rows` adds the attitude bound, which takes a time)."""
    return not state_finite or not math.isfinite(position_error_m) or \
        position_error_m > limit_m


def diverged_rows(p: np.ndarray, q: np.ndarray, p_d: np.ndarray, q_d: np.ndarray,
                  limit_m: float, *, t_us: np.ndarray,
                  attitude_limit_rad: float = DIVERGENCE_ATTITUDE_RAD,
                  attitude_hold_s: float = DIVERGENCE_ATTITUDE_HOLD_S) -> np.ndarray:
    """Rows of truth (p ENU m, q (w, x, y, z)) joined with desired (p_d, q_d) at times t_us
    that have diverged: `diverged` (a state that is not finite, a position error beyond
    limit_m) or `attitude_held` (the error angle of q_d* q above attitude_limit_rad for
    attitude_hold_s)."""
    with np.errstate(invalid="ignore", over="ignore"):
        finite = np.all(np.isfinite(np.hstack([p, q, p_d, q_d])), axis=1)
        err = np.linalg.norm(p - p_d, axis=1)
        att = angle_between_rows(q, q_d)
        held = attitude_held(t_us, att, attitude_limit_rad, attitude_hold_s)
        return np.asarray(~finite | ~np.isfinite(err) | (err > limit_m) | held)


def attitude_held(t_us: np.ndarray, error_rad: np.ndarray, limit_rad: float,
                  hold_s: float) -> np.ndarray:
    """Rows where the attitude error has stayed above limit_rad, on every row, for at least
    hold_s since the first row of that stretch (NaN counts as a break: `diverged_rows` flags
    a non-finite state by itself)."""
    with np.errstate(invalid="ignore"):
        above = np.asarray(error_rad > limit_rad)
    if not above.size:
        return above
    rows = np.arange(len(above))
    starts = np.where(above & ~np.concatenate([[False], above[:-1]]), rows, 0)
    stretch_start = np.maximum.accumulate(starts)  # first row of the stretch a row is in
    t = np.asarray(t_us, dtype=np.int64)
    return np.asarray(above & (t - t[stretch_start] >= round(hold_s * 1e6)))


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
             crash_t_us: int | None = None, stopped: str = "",
             divergence_cause: str = "") -> Outcome:
    """The status of a run from what happened to the vehicle.

    `divergence_t_us`: first instant of divergence by `diverged_rows` in the logs (None:
    never); the FCU's own divergence events count too (the earlier wins); `divergence_cause`
    (when the logs' instant is the one): what diverged, added to the reason;
    `crash_t_us`: first ground contact faster than CRASH_SPEED_M_S (None: never);
    `stopped`: "timeout" or "aborted" when the runner could not finish the run.
    A disarm in the air caused by the divergence rule counts as divergence, not as a crash.
    Events of kind LIMIT make a run that reached its end `limited` (the precedence is the
    module's).
    """
    events = list(events)
    in_air = [e.t_us for e in events if e.kind == CRASH]
    flagged = [e.t_us for e in events if e.kind == DIVERGED]  # the FCU's own judgement
    logs_t_us = divergence_t_us
    divergence_t_us = min([t for t in (divergence_t_us, *flagged) if t is not None],
                          default=None)
    crash = min([t for t in (crash_t_us, *in_air) if t is not None], default=None)
    reactions = [e for e in events if e.kind == FAILSAFE]
    first = reactions[0].text if reactions else ""
    if divergence_t_us is not None and (crash is None or divergence_t_us <= crash):
        cause = f": {divergence_cause}" if divergence_cause and logs_t_us == divergence_t_us \
            else ""
        return Outcome("diverged", first,
                       f"diverged at t = {divergence_t_us * 1e-6:.3f} s{cause}")
    if crash is not None:
        return Outcome("crashed", first, f"crashed at t = {crash * 1e-6:.3f} s")
    if stopped:
        return Outcome(stopped, first, stopped)
    if reactions:
        return Outcome("failsafe", first, f"failsafe at t = {reactions[0].t_us * 1e-6:.3f} s: "
                       f"{first}")
    if not reached_end:
        return Outcome("aborted", "", "the run ended before its end time")
    limits = [e for e in events if e.kind == LIMIT]
    if limits:
        more = f" (and {len(limits) - 1} more)" if len(limits) > 1 else ""
        return Outcome("limited", "", f"actuator limit at t = {limits[0].t_us * 1e-6:.3f} s: "
                       f"{limits[0].text}{more}")
    return Outcome("completed", "", "reached its end")
