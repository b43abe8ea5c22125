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
the measured period, the next one taken as alike). A period is one compiled call
(`monitor_kernel`, the same operations in the same order as the scalar rules above); the
notices are read from its state only in a period that brings one.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from common.jit import compiled_for, njit
from common.warm_ups import warm_up

TILT_TOLERANCE_RAD = 1e-5  # above the float32 rounding of the tilts on the simulator link
TIME_TOLERANCE_S = 1e-9  # a sum of periods equal to the time is not longer than it

# The monitor's state, one row each over its 2n actuators (tilts 0..n-1, rotors n..2n-1)
MODEL = 0  # the servos' tilts by the model (tilts only)
LIMITED_S = 1  # the current episode's consecutive limited time
REPORTED = 2  # 1: the episode was reported
START = 3  # tilt: the model at the episode's start
PEAK = 4  # rotor: the episode's highest unclamped speed
LIMITED = 5  # 1: limited in the last period
NEW = 6  # 1: reported in the last period (a notice)
NOTICE = 7  # the notice's figure: tilt the command's mean rate, rotor its peak
SETTINGS = 8  # [tilt rate limit R, w_max, the allocation's hold speed]
ROWS = 9
# What a period brought (`monitor_kernel`'s answer)
ANY_TILT_LIMITED = 1
ANY_NOTICE = 2
CLEARED = 4


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
    sqrt = math.sqrt
    return tuple([sqrt(sqrt(omega_sq[2 * i] * omega_sq[2 * i] +
                            omega_sq[2 * i + 1] * omega_sq[2 * i + 1]))
                  for i in range(len(omega_sq) // 2)])


@njit
def _timed(st: np.ndarray, k: int, dt_s: float, limit_s: float) -> bool:
    """Actuator k limited in a period: its episode is longer by dt_s; true once it has
    lasted longer than limit_s (then reported until it ends)."""
    st[LIMITED_S, k] += dt_s
    if st[REPORTED, k] != 0.0 or st[LIMITED_S, k] <= limit_s + TIME_TOLERANCE_S:
        return False
    st[REPORTED, k] = 1.0
    return True


@njit
def _tilts(st: np.ndarray, dt_s: float, limit_s: float, tilt_cmd_rad: tuple[float, ...],
           w: np.ndarray) -> int:
    """The servos' models over the period, each episode timed (the tilt rules above)."""
    n = st.shape[1] // 2
    step = st[SETTINGS, 0] * dt_s
    tolerance = step + TILT_TOLERANCE_RAD
    hold = st[SETTINGS, 2]
    flags = 0
    for i in range(n):
        c, m = tilt_cmd_rad[i], st[MODEL, i]
        gap = c - m
        limited = abs(gap) > tolerance and w[i] >= hold
        st[MODEL, i] = m + step if gap > step else (m - step if gap < -step else c)
        st[LIMITED, i] = 1.0 if limited else 0.0
        if not limited:
            st[LIMITED_S, i], st[REPORTED, i] = 0.0, 0.0
            continue
        flags |= ANY_TILT_LIMITED
        if st[LIMITED_S, i] == 0.0:
            st[START, i] = m
        if _timed(st, i, dt_s, limit_s):
            st[NEW, i], st[NOTICE, i] = 1.0, abs(c - st[START, i]) / st[LIMITED_S, i]
            flags |= ANY_NOTICE
    return flags


@njit
def _rotors(st: np.ndarray, dt_s: float, limit_s: float, w: np.ndarray) -> int:
    """The rotors' speeds against w_max over the period, each episode timed."""
    n = st.shape[1] // 2
    speed_max = st[SETTINGS, 1]
    flags = 0
    for i in range(n):
        k = n + i
        limited = w[i] > speed_max
        st[LIMITED, k] = 1.0 if limited else 0.0
        if not limited:
            st[LIMITED_S, k], st[REPORTED, k] = 0.0, 0.0
            continue
        if st[LIMITED_S, k] > 0.0:  # max(peak, w) as Python's builtin gives it
            st[PEAK, k] = w[i] if w[i] > st[PEAK, k] else st[PEAK, k]
        else:
            st[PEAK, k] = w[i]
        if _timed(st, k, dt_s, limit_s):
            st[NEW, k], st[NOTICE, k] = 1.0, st[PEAK, k]
            flags |= ANY_NOTICE
    return flags


@njit
def monitor_kernel(st: np.ndarray, dt_s: float, limit_s: float,
                   tilt_cmd_rad: tuple[float, ...], speeds: tuple[float, ...],
                   omega_sq: bool) -> int:
    """One control period of dt_s > 0 with these commands (tilts as sent; rotor speeds
    before the clamp, or with `omega_sq` eq. (28)'s Omega pairs, the speeds taken from them
    as `unclamped_speeds` does): the models advance, each actuator's episode is timed, a
    report is flagged in row NEW with its figure in row NOTICE. Returns ANY_TILT_LIMITED |
    ANY_NOTICE | CLEARED as they happened."""
    n = st.shape[1] // 2
    was_reported = False
    for k in range(2 * n):
        st[NEW, k] = 0.0
        was_reported = was_reported or st[REPORTED, k] != 0.0
    w = np.empty(n)
    for i in range(n):
        if omega_sq:
            x, y = speeds[2 * i], speeds[2 * i + 1]
            w[i] = math.sqrt(math.sqrt(x * x + y * y))
        else:
            w[i] = speeds[i]
    flags = _tilts(st, dt_s, limit_s, tilt_cmd_rad, w) | _rotors(st, dt_s, limit_s, w)
    if was_reported and not np.any(st[REPORTED] != 0.0):
        flags |= CLEARED
    return flags


def _floats(values: Sequence[float]) -> tuple[float, ...]:
    return tuple([float(v) for v in values])


class ActuatorMonitor:
    """Tilt servos (a rate-limited model driven by the commands) and rotor speeds (clamped
    at w_max), each timed in consecutive limited periods; their state in one array (rows
    MODEL ... SETTINGS) for the compiled period."""

    def __init__(self, n_rotors: int, tilt_rate_max_rad_s: float,
                 rotor_speed_max_rad_s: float, hold_speed_rad_s: float,
                 tilt_rad: Sequence[float] | None = None) -> None:
        self.n = n_rotors
        self.tilt_rate_max = tilt_rate_max_rad_s
        self.speed_max = rotor_speed_max_rad_s
        self.hold_speed = hold_speed_rad_s
        self.st = np.zeros((ROWS, 2 * n_rotors))
        self.st[SETTINGS, :3] = (tilt_rate_max_rad_s, rotor_speed_max_rad_s, hold_speed_rad_s)
        self.any_tilt_limited = False  # in the last period
        self.reset((0.0,) * n_rotors if tilt_rad is None else tilt_rad)
        warm_up("fcu.safety.actuator_monitor", self._warm_up)
        # the kernel's machine code for speeds and for Omega pairs (`compiled_for`)
        n = n_rotors
        self._kernels = (compiled_for(monitor_kernel, self.st, 0.0, 0.0, (0.0,) * n,
                                      (0.0,) * n, False),
                         compiled_for(monitor_kernel, self.st, 0.0, 0.0, (0.0,) * n,
                                      (0.0,) * (2 * n), True))

    def _warm_up(self) -> None:
        """The kernel once on a scratch state, with both kinds of speeds, on tuples of the
        pipeline's length (N_ROTORS) as a flight passes them."""
        st = self.st.copy()
        n = self.n
        monitor_kernel(st, 1e-3, 0.1, (0.0,) * n, (1.0,) * n, False)
        monitor_kernel(st, 1e-3, 0.1, (0.0,) * n, (1.0,) * (2 * n), True)

    def reset(self, tilt_rad: Sequence[float]) -> None:
        """The servos settled at these tilts (the commanded ones, at arming and while
        disarmed); episodes end without a notice."""
        st, n = self.st, self.n
        st[MODEL, :n] = [float(a) for a in tilt_rad]
        st[LIMITED_S] = st[REPORTED] = st[LIMITED] = 0.0
        self.any_tilt_limited = False

    @property
    def model_rad(self) -> list[float]:
        values: list[float] = self.st[MODEL, :self.n].tolist()
        return values

    @property
    def limited_s(self) -> list[float]:
        """Per actuator (tilts, then rotors): the current episode's consecutive limited
        time."""
        values: list[float] = self.st[LIMITED_S].tolist()
        return values

    @property
    def reported(self) -> list[bool]:
        return [x != 0.0 for x in self.st[REPORTED].tolist()]

    @property
    def tilt_limited(self) -> list[bool]:
        """Per servo: limited in the last period."""
        return [x != 0.0 for x in self.st[LIMITED, :self.n].tolist()]

    @property
    def rotor_limited(self) -> list[bool]:
        return [x != 0.0 for x in self.st[LIMITED, self.n:].tolist()]

    def update(self, dt_s: float, tilt_cmd_rad: Sequence[float],
               speed_unclamped_rad_s: Sequence[float], limit_s: float) -> list[LimitNotice]:
        """One control period of dt_s with these commands (tilts as sent, rotor speeds
        before the clamp): the notices it brings (usually none). The models advance."""
        return self._period(dt_s, _floats(tilt_cmd_rad), _floats(speed_unclamped_rad_s),
                            limit_s, False)

    def update_from_allocation(self, dt_s: float, tilt_cmd_rad: tuple[float, ...],
                               omega_sq: tuple[float, ...], limit_s: float
                               ) -> list[LimitNotice]:
        """`update` with the rotor speeds given as eq. (28)'s Omega pairs (the allocation's
        `omega_sq`, floats), the control step's path."""
        return self._period(dt_s, tilt_cmd_rad, omega_sq, limit_s, True)

    def _period(self, dt_s: float, tilts: tuple[float, ...], speeds: tuple[float, ...],
                limit_s: float, omega_sq: bool) -> list[LimitNotice]:
        if not dt_s > 0.0:
            return []
        n = self.n
        if len(tilts) != n or len(speeds) != (2 * n if omega_sq else n):
            raise ValueError(f"expected {n} tilts and {2 * n if omega_sq else n} speeds, got "
                             f"{len(tilts)} and {len(speeds)}")
        flags = self._kernels[omega_sq](self.st, float(dt_s), float(limit_s), tilts, speeds,
                                        omega_sq)
        self.any_tilt_limited = bool(flags & ANY_TILT_LIMITED)
        if not flags & (ANY_NOTICE | CLEARED):
            return []
        new, figures = self.st[NEW].tolist(), self.st[NOTICE].tolist()
        notices = [LimitNotice("tilt", i, figures[i], self.tilt_rate_max)
                   for i in range(n) if new[i]]
        notices += [LimitNotice("rotor", i, figures[n + i], self.speed_max)
                    for i in range(n) if new[n + i]]
        if flags & CLEARED:
            notices.append(LimitNotice("clear"))
        return notices
