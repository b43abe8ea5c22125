"""The commanded actuators against their models, in flight (parameter COM_ACT_RATE_T).

The FCU has no servo feedback, so each tilt servo is modelled from the commands sent, by the
plant's law (docs/model.md#plant, sitl/plant.py `tilt_servo_kernel`): over a control period of
dt the servo moves towards the held command by at most R dt (R = tilt_rate_max_rad_s) and lands on
it when it is closer; tilts are continuous (unwrapped), never wrapped. A servo is
rate-limited in a period when its model cannot reach the command in that period,
|cmd - model| > R dt (to TILT_TOLERANCE_RAD). Below the allocation's hold speed a rotor's
tilt is held by the allocation (its thrust direction is undefined), so its servo is not
judged then (its model still moves). A rotor is at its limit in a period when the
allocation clamped its speed to w_max (the allocation's `saturated`, per rotor).

An actuator limited in consecutive periods for longer than COM_ACT_RATE_T is reported once
per episode; when no reported actuator is limited any more, the limits are "cleared".
Monitor only: the commands are not changed. Pure: dt comes in as an argument (in real time
the measured period, the next one taken as alike).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

TILT_TOLERANCE_RAD = 1e-5  # above the float32 rounding of the tilts on the simulator link
TIME_TOLERANCE_S = 1e-9  # a sum of periods equal to the time is not longer than it


class LimitNotice(NamedTuple):
    """An actuator limited for longer than the time (`kind` "tilt" or "rotor", `actuator`
    0-based), or the end of all reported limits (`kind` "clear")."""

    kind: str
    actuator: int = -1
    demanded: float = 0.0  # tilt: the command's mean rate over the episode, rad/s;
    # rotor: the highest unclamped speed of the episode, rad/s
    limit: float = 0.0  # tilt: R, rad/s; rotor: w_max, rad/s

    def text(self, limit_s: float) -> str:
        """The STATUSTEXT (at most 50 characters; actuators numbered from 1)."""
        if self.kind == "tilt":
            return (f"tilt servo {self.actuator + 1} rate-limited {limit_s:g} s: "
                    f"{_figure(self.demanded)} > {self.limit:g} rad/s")
        if self.kind == "rotor":
            return (f"rotor {self.actuator + 1} at speed limit {limit_s:g} s: "
                    f"{self.demanded:.0f} > {self.limit:.0f} rad/s")
        return "actuator limits cleared"


def _figure(x: float) -> str:
    return f"{x:.1f}" if x < 99.95 else f"{x:.0f}"


def unclamped_speeds(omega_sq: Sequence[float]) -> tuple[float, ...]:
    """Each rotor's speed before the clamp to w_max, from eq. (28)'s Omega (lateral and
    vertical parts per rotor): (lat^2 + ver^2)^(1/4), as the allocation computes it."""
    sqrt, hypot = math.sqrt, math.hypot
    return tuple([sqrt(hypot(omega_sq[2 * i], omega_sq[2 * i + 1]))
                  for i in range(len(omega_sq) // 2)])


class ActuatorMonitor:
    """Tilt servos (a rate-limited model driven by the commands) and rotor speeds (clamped
    at w_max), each timed in consecutive limited periods."""

    def __init__(self, n_rotors: int, tilt_rate_max_rad_s: float,
                 rotor_speed_max_rad_s: float, hold_speed_rad_s: float,
                 tilt_rad: Sequence[float] | None = None) -> None:
        self.n = n_rotors
        self.tilt_rate_max = tilt_rate_max_rad_s
        self.speed_max = rotor_speed_max_rad_s
        self.hold_speed = hold_speed_rad_s
        self.model_rad = [0.0] * n_rotors  # the servos' tilts by the model
        # per actuator, tilts 0..n-1 then rotors n..2n-1: the current episode
        self.limited_s = [0.0] * (2 * n_rotors)  # consecutive limited time
        self.reported = [False] * (2 * n_rotors)
        self.start = [0.0] * (2 * n_rotors)  # tilt: the model at the episode's start
        self.peak = [0.0] * (2 * n_rotors)  # rotor: the highest unclamped speed
        self.tilt_limited = [False] * n_rotors  # in the last period
        self.rotor_limited = [False] * n_rotors
        self.reset((0.0,) * n_rotors if tilt_rad is None else tilt_rad)

    def reset(self, tilt_rad: Sequence[float]) -> None:
        """The servos settled at these tilts (the commanded ones, at arming and while
        disarmed); episodes end without a notice."""
        self.model_rad = [float(a) for a in tilt_rad]
        for i in range(2 * self.n):
            self.limited_s[i], self.reported[i] = 0.0, False
        self.tilt_limited = [False] * self.n
        self.rotor_limited = [False] * self.n

    def update(self, dt_s: float, tilt_cmd_rad: Sequence[float],
               speed_unclamped_rad_s: Sequence[float], limit_s: float) -> list[LimitNotice]:
        """One control period of dt_s with these commands (tilts as sent, rotor speeds
        before the clamp): the notices it brings (usually none). The models advance."""
        if not dt_s > 0.0:
            return []
        n, step = self.n, self.tilt_rate_max * dt_s
        tolerance = step + TILT_TOLERANCE_RAD
        notices: list[LimitNotice] = []
        limited_s, reported = self.limited_s, self.reported
        was_reported = any(reported)
        for i in range(n):
            c, m = tilt_cmd_rad[i], self.model_rad[i]
            gap = c - m
            limited = abs(gap) > tolerance and speed_unclamped_rad_s[i] >= self.hold_speed
            self.model_rad[i] = m + step if gap > step else (m - step if gap < -step else c)
            self.tilt_limited[i] = limited
            if not limited:
                limited_s[i], reported[i] = 0.0, False  # `_timed` of a period not limited
                continue
            if limited_s[i] == 0.0:
                self.start[i] = m
            if self._timed(i, limited, dt_s, limit_s):
                rate = abs(c - self.start[i]) / limited_s[i]
                notices.append(LimitNotice("tilt", i, rate, self.tilt_rate_max))
        for i in range(n):
            w = speed_unclamped_rad_s[i]
            limited = w > self.speed_max
            self.rotor_limited[i] = limited
            k = n + i
            if not limited:
                limited_s[k], reported[k] = 0.0, False
                continue
            self.peak[k] = max(self.peak[k], w) if limited_s[k] > 0.0 else w
            if self._timed(k, limited, dt_s, limit_s):
                notices.append(LimitNotice("rotor", i, self.peak[k], self.speed_max))
        if was_reported and not any(reported):
            notices.append(LimitNotice("clear"))
        return notices

    def _timed(self, k: int, limited: bool, dt_s: float, limit_s: float) -> bool:
        """Actuator k's episode after a period: true once it has lasted longer than
        limit_s (then reported until it ends)."""
        if not limited:
            self.limited_s[k], self.reported[k] = 0.0, False
            return False
        self.limited_s[k] += dt_s
        if self.reported[k] or self.limited_s[k] <= limit_s + TIME_TOLERANCE_S:
            return False
        self.reported[k] = True
        return True
