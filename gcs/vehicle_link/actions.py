"""Arming, mode changes by name and takeoff, the autopilot's way (`gcs.autopilot.commands`),
with its refusals as GcsError."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from common.wire.mavlink import MAV
from gcs.autopilot import Autopilot, ModeTarget
from gcs.autopilot import commands as _commands
from gcs.vehicle_link.descent import HOLDING_MODES, DescentWatch, watch_for
from gcs.vehicle_link.session import GcsError, Session

M = MAV


def _autopilot(session: Session) -> Autopilot:
    return _commands.autopilot(session)


def _observer(session: Session, floor: str) -> _commands.Observer | None:
    """The descent watch of a command on a multicopter (`gcs.vehicle_link.descent`), as an
    observer of the heights; None for other vehicles (a plane glides down by design)."""
    ap = _autopilot(session)
    if ap.vehicle != "copter":
        return None
    return _Observe(watch_for(session, ap, floor=floor))


class _Observe:
    """A descent watch as an observer of a command's wait (`gcs.autopilot.commands`)."""

    def __init__(self, watch: DescentWatch) -> None:
        self.watch = watch

    def __call__(self, msg: Any) -> None:
        self.watch.update(msg, time.monotonic())

    def pending(self) -> bool:
        return self.watch.pending


def _floor_of(target: ModeTarget) -> str:
    """A mode that holds its height is judged by its height too; one that descends by
    design (LAND, RTL, MISSION) by its speed alone."""
    return "start" if target.name in HOLDING_MODES else "none"


def set_mode(session: Session, name: str, confirm_s: float = _commands.CONFIRM_S) -> int:
    """Change mode by name: the vehicle's own names or the portable ones (`gcs.autopilot`;
    UnknownMode for a name it lacks); TAKEOFF is the takeoff procedure at its default height.
    The vehicle's answer; ACCEPTED only once a HEARTBEAT showed the mode, else GcsError
    "not confirmed: the vehicle is in X"; Unsafe when the vehicle falls meanwhile."""
    target = _autopilot(session).resolve_mode(name)
    try:
        if target.takeoff:
            try:
                return takeoff(session, _commands.DEFAULT_TAKEOFF_M, confirm_s=confirm_s)[0]
            except GcsError as exc:
                raise GcsError(f"takeoff: {exc}") from None
        return _commands.set_mode(session, target, confirm_s,
                                  _observer(session, _floor_of(target)))
    except _commands.NotConfirmed as exc:
        raise GcsError(str(exc)) from None


def takeoff(session: Session, height_m: float, *, reach_s: float | None = None,
            tolerance_m: float = 0.5, confirm_s: float = _commands.CONFIRM_S,
            report: Callable[[float], None] | None = None,
            notice: Callable[[str], None] | None = None) -> tuple[int, float | None]:
    """Take off to `height_m` above home, the autopilot's way (`gcs.autopilot.commands`);
    (the vehicle's answer, the height reached when waited for `reach_s`). GcsError for a
    vehicle disarmed or in the air, or one that does not climb; Unsafe when it loses height
    it has reached, or sinks faster than its limit."""
    try:
        return _commands.takeoff(session, height_m, reach_s=reach_s, tolerance_m=tolerance_m,
                                 confirm_s=confirm_s, report=report, fail=GcsError,
                                 observe=_observer(session, "peak"), notice=notice)
    except _commands.NotConfirmed as exc:
        raise GcsError(str(exc)) from None


def arm(session: Session, armed: bool, force: bool = False) -> int:
    return session.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0 if armed else 0.0,
                           21196.0 if force else 0.0)
