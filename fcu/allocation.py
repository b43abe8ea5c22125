"""Control allocation for tilt-rotors: geometry -> A (eq. 27) -> pseudo-inverse (eq. 28) ->
rotor speeds and tilts (eq. 29) -> unwrapped tilts (Algorithm 1, corrected; MODEL.md 2).

`LagCompensator` (parameter CA_LAG_COMP) leads those commands for the actuators the paper
takes as ideal: the rotors' first-order speed lag (unequal up and down time constants) and
the tilt servos' rate limit, by feed-forward from the reference's nominal wrench.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from common.config import VehicleConfig
from common.geometry import rotor_frames
from fcu.dualquat import Vec3, cross

TWO_PI = 2.0 * math.pi


def allocation_matrix(vehicle: VehicleConfig) -> np.ndarray:
    """The 6 x 2n static allocation matrix A: [f; tau] = A Omega, Omega = [lat_1, ver_1, ...]."""
    cf, cd = vehicle.thrust_coeff, vehicle.drag_coeff
    frames = rotor_frames(vehicle)
    a = np.zeros((6, 2 * len(frames)))
    for i, fr in enumerate(frames):
        for col, e in ((2 * i, fr.e_l_flu), (2 * i + 1, fr.e_v_flu)):
            moment = cross(fr.r_flu_m, e)
            a[:3, col] = [cf * c for c in e]
            a[3:, col] = [cf * moment[k] - fr.spin * cd * e[k] for k in range(3)]
    return a


def pseudo_inverse(a: np.ndarray) -> np.ndarray:
    """A^+ = A^T (A A^T)^-1 for a full-row-rank A (computed once)."""
    return a.T @ np.linalg.inv(a @ a.T)


def wrap_pi(x: float) -> float:
    """Wrap an angle to (-pi, pi]."""
    y = math.fmod(x + math.pi, TWO_PI)
    if y <= 0.0:
        y += TWO_PI
    return y - math.pi


class AllocationResult(NamedTuple):
    omega_sq: tuple[float, ...]  # Omega of eq. (28): lateral and vertical parts, per rotor
    speed_rad_s: tuple[float, ...]  # saturated to [0, w_max]
    tilt_raw_rad: tuple[float, ...]  # atan2 of eq. (29), in [-pi, pi]
    tilt_rad: tuple[float, ...]  # continuous tilt after unwrapping
    saturated: bool


class Allocator:
    """Pseudo-inverse allocation with speed saturation and corrected tilt unwrapping.

    The unwrapped tilt accumulates alpha*_t = alpha*_(t-1) + wrap(alpha_t - alpha*_(t-1)), which
    is continuous and equal to atan2 modulo 2 pi; below `hold_speed_rad_s` the thrust direction
    is undefined and the previous tilt is held.
    """

    def __init__(self, vehicle: VehicleConfig, initial_tilt_rad: tuple[float, ...] | None = None,
                 hold_speed_rad_s: float = 1.0) -> None:
        self.n = vehicle.n_rotors
        self.matrix = allocation_matrix(vehicle)
        self.pinv = pseudo_inverse(self.matrix)
        self._rows = tuple(tuple(float(x) for x in row) for row in self.pinv)
        self.speed_max = vehicle.rotor_speed_max_rad_s
        self.hold_speed = hold_speed_rad_s
        self.tilt: list[float] = list(initial_tilt_rad or (0.0,) * self.n)

    def reset(self, tilt_rad: tuple[float, ...]) -> None:
        self.tilt = list(tilt_rad)

    def solve(self, force_flu_n: Vec3, torque_flu_nm: Vec3) -> tuple[float, ...]:
        """Omega = A^+ [f; tau] (eq. 28), minimum-norm."""
        fx, fy, fz = force_flu_n
        tx, ty, tz = torque_flu_nm
        return tuple(a * fx + b * fy + c * fz + d * tx + e * ty + f * tz
                     for a, b, c, d, e, f in self._rows)

    def allocate(self, force_flu_n: Vec3, torque_flu_nm: Vec3) -> AllocationResult:
        """Rotor speeds and continuous tilts for a desired body wrench (eqs. 28-29)."""
        om = self.solve(force_flu_n, torque_flu_nm)
        speeds, raws = [], []
        tilt = self.tilt
        w_max, hold = self.speed_max, self.hold_speed
        saturated = False
        for i in range(self.n):
            lat, ver = om[2 * i], om[2 * i + 1]
            w = math.sqrt(math.sqrt(lat * lat + ver * ver))
            raw = math.atan2(lat, ver)
            raws.append(raw)
            if w > w_max:
                w = w_max
                saturated = True
            if w >= hold:
                tilt[i] += wrap_pi(raw - tilt[i])
            speeds.append(w)
        return AllocationResult(om, tuple(speeds), tuple(raws), tuple(tilt), saturated)


def hover_command(vehicle: VehicleConfig) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Rotor speeds and tilts that hold the vehicle level in hover (identity attitude)."""
    alloc = Allocator(vehicle)
    weight = vehicle.mass_kg * vehicle.gravity_m_s2
    result = alloc.allocate((0.0, 0.0, weight), (0.0, 0.0, 0.0))
    return result.speed_rad_s, result.tilt_rad


# ------------------------------------------------------------------ actuators that lag

LEAD_MAX_SHARE = 0.05  # a rotor speed lead (and the mean correction) is at most this share
# of w_max (a glitch bound)
MEAN_TAU_S = 0.2  # time constant of the rotors' thrust-mean correction (LagCompensator)


class ActuatorFigures(NamedTuple):
    """What the allocation knows of its actuators (MODEL.md section 2, as the plant has them):
    the rotor's first-order speed lag, w' = (c - w) / tau with tau = tau_up while c > w and
    tau_down otherwise, and the tilt servo's rate limit |alpha'| <= rate_max."""

    tau_up_s: float
    tau_down_s: float
    tilt_rate_max_rad_s: float

    @classmethod
    def of(cls, vehicle: VehicleConfig) -> ActuatorFigures:
        return cls(vehicle.rotor_tau_up_s, vehicle.rotor_tau_down_s,
                   vehicle.tilt_rate_max_rad_s)


def speed_lead(rate_rad_s2: float, figures: ActuatorFigures) -> float:
    """Lead that makes a first-order rotor lag follow a speed ramp of `rate_rad_s2` without
    steady lag: tau * w', with tau_up on a rising ramp and tau_down on a falling one.

    For c(t) = w_d(t) + tau w_d', w' = (c - w) / tau has the solution w = w_d (c - w = tau w_d'
    keeps the sign of w_d', so the constant that applies is the ramp's). Under a zero-order
    hold the period means agree exactly: the lag filters the hold's staircase, whose ramp part
    it delays by tau (undone by the lead) and whose periodic part keeps its mean (DC gain 1),
    so the lagged rotor's mean over each period equals the held command of an ideal rotor.
    """
    return (figures.tau_up_s if rate_rad_s2 > 0.0 else figures.tau_down_s) * rate_rad_s2


def rotor_period(w0: float, c: float, dt_s: float,
                 figures: ActuatorFigures) -> tuple[float, float]:
    """A rotor at w0 under a command c held for dt_s (MODEL.md 2's lag, exact): its speed at
    the end and its mean of w^2 (thrust) over the period. The speed moves towards c without
    crossing it, so one constant applies all period: w(t) = c + d e^(-t/tau), d = w0 - c, and
    mean w^2 = c^2 + 2 c d tau (1 - E) / dt + d^2 tau (1 - E^2) / (2 dt), E = e^(-dt/tau)."""
    tau = figures.tau_up_s if c > w0 else figures.tau_down_s
    e = math.exp(-dt_s / tau)
    d = w0 - c
    k = tau / dt_s
    return c + d * e, c * c + 2.0 * c * d * k * (1.0 - e) + 0.5 * d * d * k * (1.0 - e * e)


def tilt_lead(rate_rad_s: float, dt_s: float, figures: ActuatorFigures) -> float:
    """Lead of a tilt command for a tilt ramp of `rate_rad_s`, held for dt_s per command.

    A servo limited to R = rate_max moves from its last command to the next, Delta = r dt
    away, in |Delta| / R and stays there: over the period its mean falls short of the held
    command (an ideal servo's) by Delta |Delta| / (2 R dt) = r |r| dt / (2 R). Commanding that
    much further ahead makes the mean equal again; a ramp at or beyond R (the servo moves at
    its limit all period) is led by the most a period's mean can gain, R dt / 2.
    """
    r_max = figures.tilt_rate_max_rad_s
    if abs(rate_rad_s) >= r_max:
        return math.copysign(0.5 * r_max * dt_s, rate_rad_s)
    return rate_rad_s * abs(rate_rad_s) * dt_s / (2.0 * r_max)


class LagCompensator:
    """Feed-forward lead of the allocation's commands for the actuators' lag (CA_LAG_COMP 1).

    The plain allocation (eqs. 28-29) commands the speeds and tilts that give the desired
    wrench at once, as if rotors and servos were ideal; the plant's rotors lag (MODEL.md 2)
    and its servos are rate limited, so on a moving reference the wrench comes late. The lead
    is taken from the reference alone, never from the measured state: the nominal wrench of
    the reference (f_b = m R_d^T (a_d - g_W), tau_b = J omega_d' + omega_d x J omega_d) is
    allocated by eq. (28) (Omega_ff = A^+ [f_b; tau_b]) and split by eq. (29) into nominal
    speeds w_ff,i = |Omega_ff,i|^(1/2) and tilts alpha_ff,i = atan2(lat_i, ver_i); their rates
    are differenced between control periods (the reference is smooth and noise-free), and

        w_cmd,i = w_i + clamp(tau_i w_ff,i', +-LEAD_MAX_SHARE w_max)   (`speed_lead`)
        alpha_cmd,i = alpha_i + r |r| dt / (2 R),  r = alpha_ff,i'      (`tilt_lead`)

    with w_i, alpha_i the plain allocation of the tracker's wrench. The feedback part of the
    command passes with gain 1, so sensor noise is not amplified (a model inverse on the whole
    command, w_model + (w - w_model) / (1 - exp(-dt / tau)), multiplies it by ~7). A tilt below
    the hold speed is not led (its direction is undefined).

    Unequal up and down constants also rectify whatever jitters in the command (sensor noise
    through the feedback): a rotor rises faster than it falls, so its mean thrust exceeds the
    command's. An internal model of each rotor, driven by the commands sent (`rotor_period`,
    the plant's law; it starts at the first command, as if settled), gives each period's mean
    thrust m_i = mean w^2; a slow correction b_i removes the difference to the ideal rotor's,
    w_i^2:

        w_cmd,i = w_i + lead_i - b_i,   b_i <- b_i + (dt / T) (m_i - w_i^2) / (2 w_i),

    T = MEAN_TAU_S (8 tau_down), held while the command is clamped. Its input is the lagged
    minus the unlagged command, which has no low-frequency content but the bias, so b_i adds
    at most ~tau / T of the noise, slowly. Pure: dt comes in as an argument.
    """

    def __init__(self, vehicle: VehicleConfig, hold_speed_rad_s: float = 1.0) -> None:
        self.figures = ActuatorFigures.of(vehicle)
        pinv = pseudo_inverse(allocation_matrix(vehicle))
        self.pinv_rows = tuple(tuple(float(x) for x in row) for row in pinv)
        self.speed_max = vehicle.rotor_speed_max_rad_s
        self.lead_max = LEAD_MAX_SHARE * self.speed_max
        self.hold_speed = hold_speed_rad_s
        self._last: tuple[tuple[float, ...], tuple[float, ...]] | None = None
        self.model: list[float] | None = None  # the rotors' speeds by the internal model
        self.mean_bias: list[float] = [0.0] * vehicle.n_rotors  # b_i

    def reset(self) -> None:
        """Forget the last nominal speeds and tilts (the next period is not led), the rotor
        model and the mean correction."""
        self._last = None
        self.model = None
        self.mean_bias = [0.0] * len(self.mean_bias)

    def nominal(self, force_flu_n: Vec3,
                torque_flu_nm: Vec3) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """Speeds and atan2 tilts of a (nominal) wrench by eqs. (28-29), without unwrapping."""
        fx, fy, fz = force_flu_n
        tx, ty, tz = torque_flu_nm
        om = [a * fx + b * fy + c * fz + d * tx + e * ty + f * tz
              for a, b, c, d, e, f in self.pinv_rows]
        lat, ver = om[0::2], om[1::2]
        return (tuple(math.sqrt(math.sqrt(x * x + y * y)) for x, y in zip(lat, ver, strict=True)),
                tuple(math.atan2(x, y) for x, y in zip(lat, ver, strict=True)))

    def lead(self, force_ff_n: Vec3, torque_ff_nm: Vec3,
             dt_s: float) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """Speed and tilt leads for this period from the reference's nominal wrench (zero on
        the first period after `reset`, and for a period without positive dt)."""
        speeds, tilts = self.nominal(force_ff_n, torque_ff_nm)
        last, self._last = self._last, (speeds, tilts)
        n = len(speeds)
        if last is None or not dt_s > 0.0:
            return (0.0,) * n, (0.0,) * n
        fig, lim, hold = self.figures, self.lead_max, self.hold_speed
        w_lead, a_lead = [], []
        for w, a, w0, a0 in zip(speeds, tilts, *last, strict=True):
            lw = speed_lead((w - w0) / dt_s, fig)
            w_lead.append(lim if lw > lim else (-lim if lw < -lim else lw))
            a_lead.append(tilt_lead(wrap_pi(a - a0) / dt_s, dt_s, fig)
                          if w >= hold and w0 >= hold else 0.0)
        return tuple(w_lead), tuple(a_lead)

    def apply(self, plain: AllocationResult, w_lead: tuple[float, ...],
              a_lead: tuple[float, ...], dt_s: float) -> AllocationResult:
        """The plain allocation with the leads added and the mean correction taken off:
        speeds clamped to [0, w_max] (the lead does not count as saturation), tilts led only
        where the plain one is not held; then the rotor model and the correction advance by
        the period dt_s under the speeds sent."""
        w_max, hold = self.speed_max, self.hold_speed
        bias = self.mean_bias
        speeds = []
        for w, lw, b in zip(plain.speed_rad_s, w_lead, bias, strict=True):
            c = w + lw - b
            speeds.append(0.0 if c < 0.0 else (w_max if c > w_max else c))
        model = self.model if self.model is not None else list(speeds)
        if dt_s > 0.0:
            fig, lim, gain = self.figures, self.lead_max, dt_s / MEAN_TAU_S
            for i, (w, c) in enumerate(zip(plain.speed_rad_s, speeds, strict=True)):
                model[i], mean_sq = rotor_period(model[i], c, dt_s, fig)
                if 0.0 < c < w_max and w >= hold:
                    b = bias[i] + gain * (mean_sq - w * w) / (2.0 * w)
                    bias[i] = lim if b > lim else (-lim if b < -lim else b)
        self.model = model
        tilts = tuple(a + (la if w >= hold else 0.0)
                      for a, la, w in zip(plain.tilt_rad, a_lead, plain.speed_rad_s,
                                          strict=True))
        return plain._replace(speed_rad_s=tuple(speeds), tilt_rad=tilts)
