"""Control allocation for tilt-rotors: geometry -> A (eq. 27) -> pseudo-inverse (eq. 28) ->
rotor speeds and tilts (eq. 29) -> unwrapped tilts (Algorithm 1, corrected; docs/model.md#geometry).

`LagCompensator` (parameter CA_LAG_COMP) leads those commands for the actuators the paper
takes as ideal: the rotors' first-order speed lag (unequal up and down time constants) and
the tilt servos' rate limit, by feed-forward from the reference's nominal wrench.

The per-step maths are compiled kernels (numba) on flat float arrays (`allocate_kernel`,
`lead_kernel`, `apply_kernel`); the classes keep their parameters and state in arrays that
the flight core's fused step uses directly, and their methods are the typed Python face.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from common.config.vehicle import VehicleConfig
from common.geometry import rotor_frames
from common.jit import njit
from common.vehicle_constants import N_ROTORS
from fcu.control.dualquat import Vec3, cross
from fcu.control.layouts import (
    A_HOLD,
    A_PINV,
    A_SIZE,
    A_WMAX,
    ALLOC_OUT,
    ALLOC_PARAMS,
    AO_OMEGA,
    AO_SATURATED,
    AO_SIZE,
    AO_SPEED,
    AO_TILT,
    AO_TILT_RAW,
    L_HOLD,
    L_LEAD_MAX,
    L_SIZE,
    L_TAU_DOWN,
    L_TAU_UP,
    L_TILT_RATE,
    L_WMAX,
    LAG_PARAMS,
    LAG_STATE,
    LS_A_LAST,
    LS_BIAS,
    LS_HAS_LAST,
    LS_HAS_MODEL,
    LS_MODEL,
    LS_SIZE,
    LS_W_LAST,
)

TWO_PI = 2.0 * math.pi
WRENCH_SIZE = 6  # [f; tau]: force xyz, torque xyz


def allocation_matrix(vehicle: VehicleConfig) -> np.ndarray:
    """The 6 x 2n static allocation matrix A: [f; tau] = A Omega, Omega = [lat_1, ver_1, ...]."""
    cf, cd = vehicle.thrust_coeff, vehicle.drag_coeff
    frames = rotor_frames(vehicle)
    a = np.zeros((WRENCH_SIZE, 2 * len(frames)))
    for i, fr in enumerate(frames):
        for col, e in ((2 * i, fr.e_l_flu), (2 * i + 1, fr.e_v_flu)):
            moment = cross(fr.r_flu_m, e)
            a[:3, col] = [cf * c for c in e]
            a[3:, col] = [cf * moment[k] - fr.spin * cd * e[k] for k in range(3)]
    return a


def pseudo_inverse(a: np.ndarray) -> np.ndarray:
    """A^+ = A^T (A A^T)^-1 for a full-row-rank A (computed once)."""
    return a.T @ np.linalg.inv(a @ a.T)


@njit
def wrap_pi(x: float) -> float:
    """Wrap an angle to (-pi, pi]."""
    y = float(np.fmod(x + math.pi, TWO_PI))
    if y <= 0.0:
        y += TWO_PI
    return y - math.pi


class AllocationResult(NamedTuple):
    omega_sq: tuple[float, ...]  # Omega of eq. (28): lateral and vertical parts, per rotor
    speed_rad_s: tuple[float, ...]  # saturated to [0, w_max]
    tilt_raw_rad: tuple[float, ...]  # atan2 of eq. (29), in [-pi, pi]
    tilt_rad: tuple[float, ...]  # continuous tilt after unwrapping
    saturated: bool


assert ALLOC_OUT.names() == AllocationResult._fields  # allocation_result reads them in order


@njit
def solve_kernel(ap: np.ndarray, w6: np.ndarray, om: np.ndarray) -> None:
    """Omega = A^+ [f; tau] (eq. 28), minimum-norm, into om (2 n); A^+ row-major at the
    start of `ap` (the allocator's or the compensator's parameters)."""
    fx, fy, fz, tx, ty, tz = w6[0], w6[1], w6[2], w6[3], w6[4], w6[5]
    for r in range(2 * N_ROTORS):
        j = A_PINV + WRENCH_SIZE * r
        om[r] = (ap[j] * fx + ap[j + 1] * fy + ap[j + 2] * fz + ap[j + 3] * tx
                 + ap[j + 4] * ty + ap[j + 5] * tz)


@njit
def allocate_kernel(ap: np.ndarray, w6: np.ndarray, tilt: np.ndarray, out: np.ndarray) -> None:
    """Eqs. (28-29) with saturation and the corrected unwrap (Algorithm 1,
    docs/model.md#geometry) for the wrench w6 = [f; tau]; `tilt` (n) is the unwrapped tilt,
    advanced in place; `out` gets ALLOC_OUT (fcu.control.layouts), from the parameters
    ALLOC_PARAMS `ap`."""
    solve_kernel(ap, w6, out[AO_OMEGA:AO_OMEGA + 2 * N_ROTORS])
    w_max, hold = ap[A_WMAX], ap[A_HOLD]
    saturated = 0.0
    for i in range(N_ROTORS):
        lat, ver = out[AO_OMEGA + 2 * i], out[AO_OMEGA + 2 * i + 1]
        w = math.sqrt(math.sqrt(lat * lat + ver * ver))
        raw = math.atan2(lat, ver)
        out[AO_TILT_RAW + i] = raw
        if w > w_max:
            w = w_max
            saturated = 1.0
        if w >= hold:
            tilt[i] += wrap_pi(raw - tilt[i])
        out[AO_SPEED + i] = w
        out[AO_TILT + i] = tilt[i]
    out[AO_SATURATED] = saturated


def allocation_result(out: list[float]) -> AllocationResult:
    """AllocationResult of allocate_kernel's ALLOC_OUT values (as Python floats)."""
    n = N_ROTORS
    return AllocationResult(tuple(out[AO_OMEGA:AO_OMEGA + 2 * n]),
                            tuple(out[AO_SPEED:AO_SPEED + n]),
                            tuple(out[AO_TILT_RAW:AO_TILT_RAW + n]),
                            tuple(out[AO_TILT:AO_TILT + n]), out[AO_SATURATED] != 0.0)


def pinv_params(vehicle: VehicleConfig) -> np.ndarray:
    """A^+ of the vehicle, row-major (PINV_SIZE values)."""
    return np.ascontiguousarray(pseudo_inverse(allocation_matrix(vehicle))).reshape(-1)


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
        self.speed_max = vehicle.rotor_speed_max_rad_s
        self.hold_speed = hold_speed_rad_s
        self.params = np.zeros(A_SIZE)
        ALLOC_PARAMS.view(self.params, "pinv")[:] = pinv_params(vehicle)
        self.params[A_WMAX], self.params[A_HOLD] = self.speed_max, hold_speed_rad_s
        self.tilt_array = np.array(initial_tilt_rad or (0.0,) * self.n, dtype=np.float64)

    @property
    def tilt(self) -> list[float]:
        """The unwrapped tilts (a copy)."""
        return list(self.tilt_array.tolist())

    def reset(self, tilt_rad: tuple[float, ...]) -> None:
        self.tilt_array[:] = tilt_rad

    def bind(self, params: np.ndarray, tilt: np.ndarray) -> None:
        """Keep parameters and tilts in these arrays from now on (views of a fused step's
        buffers), with their current values."""
        params[:] = self.params
        tilt[:] = self.tilt_array
        self.params, self.tilt_array = params, tilt

    def allocate(self, force_flu_n: Vec3, torque_flu_nm: Vec3) -> AllocationResult:
        """Rotor speeds and continuous tilts for a desired body wrench (eqs. 28-29)."""
        out = np.empty(AO_SIZE)
        allocate_kernel(self.params,
                        np.array((*force_flu_n, *torque_flu_nm), dtype=np.float64),
                        self.tilt_array, out)
        return allocation_result(out.tolist())


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
    """What the allocation knows of its actuators (docs/model.md#plant):
    the rotor's first-order speed lag, w' = (c - w) / tau with tau = tau_up while c > w and
    tau_down otherwise, and the tilt servo's rate limit |alpha'| <= rate_max."""

    tau_up_s: float
    tau_down_s: float
    tilt_rate_max_rad_s: float

    @classmethod
    def of(cls, vehicle: VehicleConfig) -> ActuatorFigures:
        return cls(vehicle.rotor_tau_up_s, vehicle.rotor_tau_down_s,
                   vehicle.tilt_rate_max_rad_s)


@njit
def speed_lead(rate_rad_s2: float, figures: tuple[float, float, float]) -> float:
    """Lead that makes a first-order rotor lag follow a speed ramp of `rate_rad_s2` without
    steady lag: tau * w', with tau_up on a rising ramp and tau_down on a falling one.

    For c(t) = w_d(t) + tau w_d', w' = (c - w) / tau has the solution w = w_d (c - w = tau w_d'
    keeps the sign of w_d', so the constant that applies is the ramp's). Under a zero-order
    hold the period means agree exactly: the lag filters the hold's staircase, whose ramp part
    it delays by tau (undone by the lead) and whose periodic part keeps its mean (DC gain 1),
    so the lagged rotor's mean over each period equals the held command of an ideal rotor.
    """
    return (figures[0] if rate_rad_s2 > 0.0 else figures[1]) * rate_rad_s2


@njit
def rotor_period(w0: float, c: float, dt_s: float,
                 figures: tuple[float, float, float]) -> tuple[float, float]:
    """A rotor at w0 under a command c held for dt_s (docs/model.md#plant: the lag, exact): its
    speed at the end and its mean of w^2 (thrust) over the period. The speed moves towards c without
    crossing it, so one constant applies all period: w(t) = c + d e^(-t/tau), d = w0 - c, and
    mean w^2 = c^2 + 2 c d tau (1 - E) / dt + d^2 tau (1 - E^2) / (2 dt), E = e^(-dt/tau)."""
    tau = figures[0] if c > w0 else figures[1]
    e = math.exp(-dt_s / tau)
    d = w0 - c
    k = tau / dt_s
    return c + d * e, c * c + 2.0 * c * d * k * (1.0 - e) + 0.5 * d * d * k * (1.0 - e * e)


@njit
def tilt_lead(rate_rad_s: float, dt_s: float, figures: tuple[float, float, float]) -> float:
    """Lead of a tilt command for a tilt ramp of `rate_rad_s`, held for dt_s per command.

    A servo limited to R = rate_max moves from its last command to the next, Delta = r dt
    away, in |Delta| / R and stays there: over the period its mean falls short of the held
    command (an ideal servo's) by Delta |Delta| / (2 R dt) = r |r| dt / (2 R). Commanding that
    much further ahead makes the mean equal again; a ramp at or beyond R (the servo moves at
    its limit all period) is led by the most a period's mean can gain, R dt / 2.
    """
    r_max = figures[2]
    if abs(rate_rad_s) >= r_max:
        return math.copysign(0.5 * r_max * dt_s, rate_rad_s)
    return rate_rad_s * abs(rate_rad_s) * dt_s / (2.0 * r_max)


class LagCompensator:
    """Feed-forward lead of the allocation's commands for the actuators' lag (CA_LAG_COMP 1).

    The plain allocation (eqs. 28-29) commands the speeds and tilts that give the desired
    wrench at once, as if rotors and servos were ideal; the plant's rotors lag (docs/model.md#plant)
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
        self.speed_max = vehicle.rotor_speed_max_rad_s
        self.lead_max = LEAD_MAX_SHARE * self.speed_max
        self.hold_speed = hold_speed_rad_s
        cp = self.params = np.zeros(L_SIZE)
        LAG_PARAMS.view(cp, "pinv")[:] = pinv_params(vehicle)
        cp[L_WMAX], cp[L_LEAD_MAX], cp[L_HOLD] = self.speed_max, self.lead_max, hold_speed_rad_s
        cp[L_TAU_UP], cp[L_TAU_DOWN], cp[L_TILT_RATE] = self.figures
        self.state = np.zeros(LS_SIZE)

    def reset(self) -> None:
        """Forget the last nominal speeds and tilts (the next period is not led), the rotor
        model and the mean correction."""
        self.state[:] = 0.0

    def bind(self, params: np.ndarray, state: np.ndarray) -> None:
        """Keep parameters and state in these arrays from now on (views of a fused step's
        buffers), with their current values."""
        params[:] = self.params
        state[:] = self.state
        self.params, self.state = params, state

    @property
    def model(self) -> list[float] | None:
        """The rotors' speeds by the internal model (None before the first command)."""
        cs = self.state
        return LAG_STATE.view(cs, "model_rad_s").tolist() if cs[LS_HAS_MODEL] else None

    @property
    def mean_bias(self) -> list[float]:
        """The mean correction b_i."""
        return list(LAG_STATE.view(self.state, "bias_rad_s").tolist())

    def nominal(self, force_flu_n: Vec3,
                torque_flu_nm: Vec3) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """Speeds and atan2 tilts of a (nominal) wrench by eqs. (28-29), without unwrapping."""
        speeds, tilts = np.empty(N_ROTORS), np.empty(N_ROTORS)
        nominal_kernel(self.params, np.array((*force_flu_n, *torque_flu_nm), dtype=np.float64),
                       speeds, tilts)
        return tuple(speeds.tolist()), tuple(tilts.tolist())

    def lead(self, force_ff_n: Vec3, torque_ff_nm: Vec3,
             dt_s: float) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """Speed and tilt leads for this period from the reference's nominal wrench (zero on
        the first period after `reset`, and for a period without positive dt)."""
        w_lead, a_lead = np.empty(N_ROTORS), np.empty(N_ROTORS)
        lead_kernel(self.params, self.state,
                    np.array((*force_ff_n, *torque_ff_nm), dtype=np.float64), float(dt_s),
                    w_lead, a_lead)
        return tuple(w_lead.tolist()), tuple(a_lead.tolist())

    def apply(self, plain: AllocationResult, w_lead: tuple[float, ...],
              a_lead: tuple[float, ...], dt_s: float) -> AllocationResult:
        """The plain allocation with the leads added and the mean correction taken off:
        speeds clamped to [0, w_max] (the lead does not count as saturation), tilts led only
        where the plain one is not held; then the rotor model and the correction advance by
        the period dt_s under the speeds sent."""
        speeds, tilts = np.empty(N_ROTORS), np.empty(N_ROTORS)
        apply_kernel(self.params, self.state,
                     np.array(plain.speed_rad_s, dtype=np.float64),
                     np.array(plain.tilt_rad, dtype=np.float64),
                     np.array(w_lead, dtype=np.float64), np.array(a_lead, dtype=np.float64),
                     float(dt_s), speeds, tilts)
        return plain._replace(speed_rad_s=tuple(speeds.tolist()),
                              tilt_rad=tuple(tilts.tolist()))


@njit
def nominal_kernel(cp: np.ndarray, w6: np.ndarray, speeds: np.ndarray,
                   tilts: np.ndarray) -> None:
    """Speeds and atan2 tilts of a (nominal) wrench w6 by eqs. (28-29), not unwrapped."""
    om = np.empty(2 * N_ROTORS)
    solve_kernel(cp, w6, om)
    for i in range(N_ROTORS):
        x, y = om[2 * i], om[2 * i + 1]
        speeds[i] = math.sqrt(math.sqrt(x * x + y * y))
        tilts[i] = math.atan2(x, y)


@njit
def lead_kernel(cp: np.ndarray, cs: np.ndarray, w6_ff: np.ndarray, dt_s: float,
                w_lead: np.ndarray, a_lead: np.ndarray) -> None:
    """LagCompensator.lead on the compensator's arrays (parameters cp, state cs)."""
    speeds, tilts = np.empty(N_ROTORS), np.empty(N_ROTORS)
    nominal_kernel(cp, w6_ff, speeds, tilts)
    n = N_ROTORS
    had_last = cs[LS_HAS_LAST] != 0.0
    w_last = cs[LS_W_LAST:LS_W_LAST + n].copy()
    a_last = cs[LS_A_LAST:LS_A_LAST + n].copy()
    cs[LS_W_LAST:LS_W_LAST + n] = speeds
    cs[LS_A_LAST:LS_A_LAST + n] = tilts
    cs[LS_HAS_LAST] = 1.0
    if not had_last or not dt_s > 0.0:
        w_lead[:] = 0.0
        a_lead[:] = 0.0
        return
    lim, hold = cp[L_LEAD_MAX], cp[L_HOLD]
    fig = (cp[L_TAU_UP], cp[L_TAU_DOWN], cp[L_TILT_RATE])
    for i in range(N_ROTORS):
        w, a, w0, a0 = speeds[i], tilts[i], w_last[i], a_last[i]
        lw = speed_lead((w - w0) / dt_s, fig)
        w_lead[i] = lim if lw > lim else (-lim if lw < -lim else lw)
        a_lead[i] = (tilt_lead(wrap_pi(a - a0) / dt_s, dt_s, fig)
                     if w >= hold and w0 >= hold else 0.0)


@njit
def apply_kernel(cp: np.ndarray, cs: np.ndarray, plain_speeds: np.ndarray,
                 plain_tilts: np.ndarray, w_lead: np.ndarray, a_lead: np.ndarray, dt_s: float,
                 speeds: np.ndarray, tilts: np.ndarray) -> None:
    """LagCompensator.apply on the compensator's arrays: led speeds and tilts out."""
    w_max, lim, hold = cp[L_WMAX], cp[L_LEAD_MAX], cp[L_HOLD]
    fig = (cp[L_TAU_UP], cp[L_TAU_DOWN], cp[L_TILT_RATE])
    bias = cs[LS_BIAS:LS_BIAS + N_ROTORS]
    model = cs[LS_MODEL:LS_MODEL + N_ROTORS]
    for i in range(N_ROTORS):
        c = plain_speeds[i] + w_lead[i] - bias[i]
        speeds[i] = 0.0 if c < 0.0 else (w_max if c > w_max else c)
    if cs[LS_HAS_MODEL] == 0.0:
        model[:] = speeds
        cs[LS_HAS_MODEL] = 1.0
    if dt_s > 0.0:
        gain = dt_s / MEAN_TAU_S
        for i in range(N_ROTORS):
            w, c = plain_speeds[i], speeds[i]
            model[i], mean_sq = rotor_period(model[i], c, dt_s, fig)
            if 0.0 < c < w_max and w >= hold:
                b = bias[i] + gain * (mean_sq - w * w) / (2.0 * w)
                bias[i] = lim if b > lim else (-lim if b < -lim else b)
    for i in range(N_ROTORS):
        tilts[i] = plain_tilts[i] + (a_lead[i] if plain_speeds[i] >= hold else 0.0)
