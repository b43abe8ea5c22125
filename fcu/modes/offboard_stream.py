"""OFFBOARD's input: the streamed targets as the commander takes them (ENU/FLU, SI units),
the limits a target must keep, and the latest sample; pure, no I/O, no MAVLink.

The FCU's MAVLink edge (`fcu.edge.setpoint_wire`) decodes SET_POSITION_TARGET_LOCAL_NED into a
`PositionTarget` and SET_ATTITUDE_TARGET into an `AttitudeTarget`: a part the message does
not give is None. `OffboardSetpoint.take_position` and `take_attitude` check a target
against the limits and keep it as the latest sample; `fcu.modes.offboard` shapes the samples into
a reference the vehicle can fly.

The stream's loss is judged as PX4 judges it: COM_OF_LOSS_T on the FCU's clock, which is
the wall clock in real time and, in PX4's lockstep SITL, simulated time. The callers pass
the wall clock (`now_s`). In lockstep the FCU gives the setpoint its flight clock
(`flight_clock`, simulated seconds) and a sample's age is the lesser of its ages on the two
clocks (`age_s`; the wall clock's alone while simulated time has not moved since it, as
before the flight starts): a ground station produces its stream at a wall-clock rate, so a
stream is lost only when it has paused for COM_OF_LOSS_T on the wall clock and the flight
has flown that long without it. A loaded machine that starves the station slows simulated
time with it, and a lockstep run faster than real time thins a wall-clock stream on the
flight clock; neither is a loss. `received_s` reads as the wall-clock time that old, for
the callers that compare it with their `now_s`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple

from fcu.control.dualquat import Quat, Vec3, norm3
from fcu.modes import offboard

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


Clock = Callable[[], float]


@dataclass
class OffboardSetpoint:
    """The latest offboard sample in ENU/FLU; None = not given.

    `flight_clock` None (real time): `received_s` is the wall-clock time of the latest
    sample, as PX4 judges it. Set (lockstep: the flight clock in seconds), the sample is
    stamped on it too and judged by `age_s`; with `wall_clock` (the clock the callers'
    `now_s` comes from) `received_s` then reads as the wall-clock time that old, so that a
    caller's `now_s - received_s` is that age. No clock is read here unless given."""

    p_enu_m: Vec3 | None = None
    v_enu_m_s: Vec3 = _ZERO
    a_enu_m_s2: Vec3 = _ZERO
    q_level_enu_flu: Quat | None = None  # the heading given with the position
    q_enu_flu: Quat | None = None
    omega_flu_rad_s: Vec3 = _ZERO
    received_wall_s: float = -math.inf  # the wall clock at the latest sample
    seq: int = 0  # counts the samples taken: the reference anchors each new one
    flight_clock: Clock | None = None  # lockstep: simulated seconds; None: real time
    received_flight_s: float = -math.inf  # the flight clock at the latest sample
    wall_clock: Clock | None = field(default=None, repr=False)  # what now_s is read from

    @property
    def received_s(self) -> float:
        """The latest sample's time on the wall clock; in lockstep the wall-clock time as
        old as the sample is (`age_s`); -inf: none yet."""
        if self.flight_clock is None or self.wall_clock is None or \
                self.received_flight_s == -math.inf:
            return self.received_wall_s
        now = self.wall_clock()
        return now - self.age_s(now)

    @received_s.setter
    def received_s(self, now_s: float) -> None:
        self.received_wall_s = now_s
        if self.flight_clock is not None:
            self.received_flight_s = self.flight_clock()

    def age_s(self, now_s: float) -> float:
        """How old the latest sample is: on the wall clock (`now_s`) in real time; in
        lockstep the lesser of its wall-clock and flight-clock ages, the wall clock's alone
        while the flight clock has not moved since the sample."""
        wall = now_s - self.received_wall_s
        if self.flight_clock is None or self.received_flight_s == -math.inf:
            return wall
        flown = self.flight_clock() - self.received_flight_s
        return wall if flown <= 0.0 else min(wall, flown)

    def lost(self, now_s: float, timeout_s: float) -> bool:
        """No sample for longer than `timeout_s` (COM_OF_LOSS_T), as `age_s` counts."""
        return self.age_s(now_s) > timeout_s

    def take_position(self, now_s: float, t: PositionTarget, max_distance_m: float) -> str:
        """Keep a position target received at `now_s` (wall clock; in lockstep also stamped on
        the flight clock); why it is refused, or
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
