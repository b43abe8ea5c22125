"""Arming, mode changes by name and takeoff, the autopilot's way (`gcs.autopilot.commands`),
with its refusals as GcsError."""

from __future__ import annotations

from collections.abc import Callable

from common.mavlink import MAV
from gcs.autopilot import Autopilot
from gcs.autopilot import commands as _commands
from gcs.session import GcsError, Session

M = MAV


def _autopilot(session: Session) -> Autopilot:
    return _commands.autopilot(session)


def set_mode(session: Session, name: str, confirm_s: float = _commands.CONFIRM_S) -> int:
    """Change mode by name: the vehicle's own names or the portable ones (`gcs.autopilot`;
    UnknownMode for a name it lacks); TAKEOFF is the takeoff procedure at its default height.
    The vehicle's answer; ACCEPTED only once a HEARTBEAT showed the mode, else GcsError
    "not confirmed: the vehicle is in X"."""
    target = _autopilot(session).resolve_mode(name)
    try:
        if target.takeoff:
            try:
                return takeoff(session, _commands.DEFAULT_TAKEOFF_M, confirm_s=confirm_s)[0]
            except GcsError as exc:
                raise GcsError(f"takeoff: {exc}") from None
        return _commands.set_mode(session, target, confirm_s)
    except _commands.NotConfirmed as exc:
        raise GcsError(str(exc)) from None


def takeoff(session: Session, height_m: float, *, reach_s: float | None = None,
            tolerance_m: float = 0.5, confirm_s: float = _commands.CONFIRM_S,
            report: Callable[[float], None] | None = None) -> tuple[int, float | None]:
    """Take off to `height_m` above home, the autopilot's way (`gcs.autopilot.commands`);
    (the vehicle's answer, the height reached when waited for `reach_s`). GcsError for a
    vehicle disarmed or in the air, or one that does not climb."""
    try:
        return _commands.takeoff(session, height_m, reach_s=reach_s, tolerance_m=tolerance_m,
                                 confirm_s=confirm_s, report=report, fail=GcsError)
    except _commands.NotConfirmed as exc:
        raise GcsError(str(exc)) from None


def arm(session: Session, armed: bool, force: bool = False) -> int:
    return session.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0 if armed else 0.0,
                           21196.0 if force else 0.0)
