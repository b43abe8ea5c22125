"""OFFBOARD's input: the streamed targets as the commander takes them (ENU/FLU, SI units),
the limits a target must keep, and the latest sample; pure, no I/O, no MAVLink.

The FCU's MAVLink edge (`fcu.setpoint_wire`) decodes SET_POSITION_TARGET_LOCAL_NED into a
`PositionTarget` and SET_ATTITUDE_TARGET into an `AttitudeTarget`: a part the message does
not give is None. `OffboardSetpoint.take_position` and `take_attitude` check a target
against the limits and keep it as the latest sample; `fcu.offboard` shapes the samples into
a reference the vehicle can fly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

from fcu import offboard
from fcu.dualquat import Quat, Vec3, norm3

_ZERO: Vec3 = (0.0, 0.0, 0.0)
# Offboard targets beyond these are refused (no vehicle of this class flies them).
MAX_OFFBOARD_SPEED_M_S = 50.0
MAX_OFFBOARD_ACC_M_S2 = 50.0
MAX_OFFBOARD_RATE_RAD_S = 50.0


class PositionTarget(NamedTuple):
    """A position target in ENU; None: the part is not given. A given part may be
    non-finite: a position that is not finite is refused, a velocity or acceleration that is
    not finite is taken as zero."""

    p_enu_m: Vec3 | None = None
    v_enu_m_s: Vec3 | None = None
    a_enu_m_s2: Vec3 | None = None
    q_level_enu_flu: Quat | None = None  # level, at the heading given (None: no heading)

    @property
    def has_position(self) -> bool:
        return self.p_enu_m is not None

    @property
    def has_velocity(self) -> bool:
        return self.v_enu_m_s is not None

    @property
    def has_acceleration(self) -> bool:
        return self.a_enu_m_s2 is not None

    @property
    def has_heading(self) -> bool:
        return self.q_level_enu_flu is not None


class AttitudeTarget(NamedTuple):
    """An attitude target: a unit quaternion ENU -> FLU and body rates (FLU); None: the part
    is not given. Rates that are not finite, or above MAX_OFFBOARD_RATE_RAD_S, are taken as
    zero."""

    q_enu_flu: Quat | None = None
    omega_flu_rad_s: Vec3 | None = None

    @property
    def has_attitude(self) -> bool:
        return self.q_enu_flu is not None

    @property
    def has_rates(self) -> bool:
        return self.omega_flu_rad_s is not None


def _finite(v: Vec3) -> bool:
    return all(map(math.isfinite, v))


@dataclass
class OffboardSetpoint:
    """The latest offboard sample in ENU/FLU; None = not given."""

    p_enu_m: Vec3 | None = None
    v_enu_m_s: Vec3 = _ZERO
    a_enu_m_s2: Vec3 = _ZERO
    q_level_enu_flu: Quat | None = None  # the heading given with the position
    q_enu_flu: Quat | None = None
    omega_flu_rad_s: Vec3 = _ZERO
    received_s: float = -math.inf
    seq: int = 0  # counts the samples taken: the reference anchors each new one

    def take_position(self, now_s: float, t: PositionTarget, max_distance_m: float) -> str:
        """Keep a position target received at `now_s` (wall clock); why it is refused, or
        "" when kept. A position beyond `max_distance_m` (GF_MAX_DIST) from home is refused,
        and so are a velocity and an acceleration above their limits."""
        if t.p_enu_m is not None and not _finite(t.p_enu_m):
            return "position target not finite"
        if t.p_enu_m is not None and norm3(t.p_enu_m) > max_distance_m:
            return "position target beyond GF_MAX_DIST"
        for vec, limit, what in ((t.v_enu_m_s, MAX_OFFBOARD_SPEED_M_S, "velocity"),
                                 (t.a_enu_m_s2, MAX_OFFBOARD_ACC_M_S2, "acceleration")):
            if vec is not None and _finite(vec) and norm3(vec) > limit:
                return f"{what} target above {limit:g}"
        if t.p_enu_m is not None:
            self.p_enu_m = t.p_enu_m
        self.v_enu_m_s = t.v_enu_m_s if t.v_enu_m_s is not None and _finite(t.v_enu_m_s) \
            else _ZERO
        self.a_enu_m_s2 = t.a_enu_m_s2 if t.a_enu_m_s2 is not None and \
            _finite(t.a_enu_m_s2) else _ZERO
        self.q_level_enu_flu = t.q_level_enu_flu
        self.received_s = now_s
        self.seq += 1
        return ""

    def take_attitude(self, now_s: float, t: AttitudeTarget) -> str:
        """Keep an attitude target received at `now_s` (wall clock); "" (it is never
        refused: rates beyond the limit are dropped)."""
        if t.q_enu_flu is not None:
            self.q_enu_flu = t.q_enu_flu
        w = t.omega_flu_rad_s
        self.omega_flu_rad_s = w if w is not None and _finite(w) and \
            norm3(w) <= MAX_OFFBOARD_RATE_RAD_S else _ZERO
        self.received_s = now_s
        self.seq += 1
        return ""

    def target(self) -> offboard.Target:
        """The sample as the shaper takes it: the attitude given, or level at the heading
        given, or None (keep the attitude)."""
        q = self.q_enu_flu if self.q_enu_flu is not None else self.q_level_enu_flu
        return offboard.Target(self.seq, self.p_enu_m, self.v_enu_m_s, self.a_enu_m_s2, q,
                               self.omega_flu_rad_s)
