"""Rigid-body plant of a tilt-rotor multirotor with rotor and tilt-servo dynamics.

Independent of the controller on purpose (no dual quaternions, no allocation matrix): the
world-frame Newton-Euler equations in ENU/FLU with gravity,
    p' = v,   m v' = R(q) f_b + m g_W,   q' = 1/2 q (0, w),   J w' = tau_b - w x J w,
integrated by fixed-step RK4 with the quaternion renormalised after each step. The rotor
wrench is the per-rotor sum F_i = c_f w_i^2 n_i, Q_i = -sigma_i c_d w_i^2 n_i (MODEL.md 2).

Actuators are decoupled from the body, so their state inside a step is known in closed form:
a first-order rotor lag (time constants up/down) towards a command clamped to [0, w_max], and
a rate-limited tilt servo, tilt(t) = a0 + clamp(c - a0, -rate t, rate t). The wrench is
evaluated on that exact actuator trajectory at the RK4 stage times. A servo that reaches its
command inside a step puts a kink in the trajectory at t = |c - a0| / rate; the step is then
split at every such instant and integrated piecewise, so that no RK4 step straddles a kink and
the actuator trajectory stays exact. `ideal_actuators` makes both follow their commands
instantly (the speed limits stay: they are physical).

Ground (z = 0): a resting vehicle stays put while the net vertical force does not lift it;
a vehicle reaching z < 0 stops there (inelastic contact, velocities zeroed).

The step is a compiled kernel (`step_kernel`, numba) on a flat state array laid out as
TRUTH_COLUMNS (so a state is its truth-log row) and a flat parameter array; `Plant.step`
is its Python face on PlantState, `Plant.step_rows` runs a control period's substeps at once.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from common.config import Scenario, VehicleConfig
from common.geometry import rotor_frames
from common.jit import njit, warm_up
from sitl.disturbance import Disturbance, disturbance_kernel

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]


class PlantState(NamedTuple):
    time_us: int
    p_enu_m: Vec3
    v_enu_m_s: Vec3  # world-frame velocity
    q_enu_flu: Quat  # rotates FLU vectors into ENU, (w, x, y, z)
    omega_flu_rad_s: Vec3
    rotor_speed_rad_s: tuple[float, ...]
    tilt_rad: tuple[float, ...]
    landed: bool


TRUTH_COLUMNS = ("time_us", "px", "py", "pz", "vx", "vy", "vz", "qw", "qx", "qy", "qz",
                 "wx", "wy", "wz", *(f"rotor{i}" for i in range(6)),
                 *(f"tilt{i}" for i in range(6)), "landed")


def truth_row(s: PlantState) -> tuple[float, ...]:
    """One row of the ground-truth log (ENU/FLU, SI units; TRUTH_COLUMNS)."""
    return (s.time_us, *s.p_enu_m, *s.v_enu_m_s, *s.q_enu_flu, *s.omega_flu_rad_s,
            *s.rotor_speed_rad_s, *s.tilt_rad, float(s.landed))


class ActuatorCommand(NamedTuple):
    rotor_speed_rad_s: tuple[float, ...]
    tilt_rad: tuple[float, ...]


@njit
def rotate(q: Quat, v: Vec3) -> Vec3:
    """R(q) v via the rotation matrix of q (the controller uses another formula)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    vx, vy, vz = v[0], v[1], v[2]
    return ((1 - 2 * (y * y + z * z)) * vx + 2 * (x * y - w * z) * vy + 2 * (x * z + w * y) * vz,
            2 * (x * y + w * z) * vx + (1 - 2 * (x * x + z * z)) * vy + 2 * (y * z - w * x) * vz,
            2 * (x * z - w * y) * vx + 2 * (y * z + w * x) * vy + (1 - 2 * (x * x + y * y)) * vz)


@njit
def rotate_inv(q: Quat, v: Vec3) -> Vec3:
    return rotate((q[0], -q[1], -q[2], -q[3]), v)


# The parameter array of the kernels (Plant.params).
_MASS, _JX, _JY, _JZ, _G, _WMAX, _TAU_UP, _TAU_DOWN, _TILT_RATE, _DT_US = range(10)
_IDEAL, _GROUND, _DECAY_UP, _DECAY_DOWN, _DECAY_HALF_UP, _DECAY_HALF_DOWN = range(10, 16)
_DIST_ACTIVE, _DIST_T0, _ROTORS = 16, 17, 18  # rotors: 12 per rotor (Plant._rotors)
PARAMS_SIZE = _ROTORS + 12 * 6
STATE_SIZE = len(TRUTH_COLUMNS)  # time_us, p, v, q, omega, rotor speeds, tilts, landed
_SPEED, _TILT, _LANDED = 14, 20, 26


@njit
def rotor_wrench_kernel(pp: np.ndarray, speeds: np.ndarray, tilts: np.ndarray
                        ) -> tuple[float, float, float, float, float, float]:
    """Sum over rotors of thrust and torque (arm moment plus drag), in FLU: (f, tau)."""
    fx = fy = fz = tx = ty = tz = 0.0
    for i in range(6):
        r = _ROTORS + 12 * i
        w = speeds[i]
        a = tilts[i]
        w2 = w * w
        c = w2 * math.cos(a)
        s = w2 * math.sin(a)
        fx += c * pp[r] + s * pp[r + 3]
        fy += c * pp[r + 1] + s * pp[r + 4]
        fz += c * pp[r + 2] + s * pp[r + 5]
        tx += c * pp[r + 6] + s * pp[r + 9]
        ty += c * pp[r + 7] + s * pp[r + 10]
        tz += c * pp[r + 8] + s * pp[r + 11]
    return (fx, fy, fz, tx, ty, tz)


@njit
def rotor_lag_kernel(w_max: float, speed0: np.ndarray, cmd: np.ndarray, decay_up: float,
                     decay_down: float, out: np.ndarray) -> None:
    """First-order lag towards the command clamped to [0, w_max], exact over the hold."""
    for i in range(len(speed0)):
        w0 = speed0[i]
        c = cmd[i]
        c = 0.0 if c < 0.0 else (w_max if c > w_max else c)
        out[i] = c + (w0 - c) * (decay_up if c > w0 else decay_down)


@njit
def tilt_servo_kernel(tilt0: np.ndarray, cmd: np.ndarray, lim: float, out: np.ndarray) -> None:
    """Rate-limited servo: moves towards the command by at most `lim` (and lands on it
    exactly, so that a servo at rest has no kink in the next step)."""
    for i in range(len(tilt0)):
        a0, c = tilt0[i], cmd[i]
        d = c - a0
        out[i] = a0 + lim if d > lim else (a0 - lim if d < -lim else c)


@njit
def derivative_kernel(pp: np.ndarray, x: tuple[float, ...], wrench: tuple[float, ...]
                      ) -> tuple[float, ...]:
    """d/dt of (p, v, q, w) in ENU/FLU under a body wrench (f, tau)."""
    vx, vy, vz = x[3], x[4], x[5]
    qw, qx, qy, qz = x[6], x[7], x[8], x[9]
    wx, wy, wz = x[10], x[11], x[12]
    fx, fy, fz, tx, ty, tz = wrench[0], wrench[1], wrench[2], wrench[3], wrench[4], wrench[5]
    inv_m = 1.0 / pp[_MASS]
    ax, ay, az = rotate((qw, qx, qy, qz), (fx * inv_m, fy * inv_m, fz * inv_m))
    jx, jy, jz = pp[_JX], pp[_JY], pp[_JZ]
    return (vx, vy, vz,
            ax, ay, az - pp[_G],
            0.5 * (-qx * wx - qy * wy - qz * wz),
            0.5 * (qw * wx + qy * wz - qz * wy),
            0.5 * (qw * wy - qx * wz + qz * wx),
            0.5 * (qw * wz + qx * wy - qy * wx),
            (tx - (jz - jy) * wy * wz) / jx,
            (ty - (jx - jz) * wz * wx) / jy,
            (tz - (jy - jx) * wx * wy) / jz)


@njit
def _axpy(x: tuple[float, ...], h: float, k: tuple[float, ...]) -> tuple[float, ...]:
    """x + h k for the 13 rigid-body states."""
    return (x[0] + h * k[0], x[1] + h * k[1], x[2] + h * k[2], x[3] + h * k[3],
            x[4] + h * k[4], x[5] + h * k[5], x[6] + h * k[6], x[7] + h * k[7],
            x[8] + h * k[8], x[9] + h * k[9], x[10] + h * k[10], x[11] + h * k[11],
            x[12] + h * k[12])


@njit
def _rk4(pp: np.ndarray, x: tuple[float, ...], h: float, wa: tuple[float, ...],
         wm: tuple[float, ...], wb: tuple[float, ...]) -> tuple[float, ...]:
    """One classical RK4 step of length h; wrench at the start, midpoint and end."""
    hh = 0.5 * h
    k1 = derivative_kernel(pp, x, wa)
    k2 = derivative_kernel(pp, _axpy(x, hh, k1), wm)
    k3 = derivative_kernel(pp, _axpy(x, hh, k2), wm)
    k4 = derivative_kernel(pp, _axpy(x, h, k3), wb)
    h6 = h / 6.0
    return (x[0] + h6 * (k1[0] + 2.0 * (k2[0] + k3[0]) + k4[0]),
            x[1] + h6 * (k1[1] + 2.0 * (k2[1] + k3[1]) + k4[1]),
            x[2] + h6 * (k1[2] + 2.0 * (k2[2] + k3[2]) + k4[2]),
            x[3] + h6 * (k1[3] + 2.0 * (k2[3] + k3[3]) + k4[3]),
            x[4] + h6 * (k1[4] + 2.0 * (k2[4] + k3[4]) + k4[4]),
            x[5] + h6 * (k1[5] + 2.0 * (k2[5] + k3[5]) + k4[5]),
            x[6] + h6 * (k1[6] + 2.0 * (k2[6] + k3[6]) + k4[6]),
            x[7] + h6 * (k1[7] + 2.0 * (k2[7] + k3[7]) + k4[7]),
            x[8] + h6 * (k1[8] + 2.0 * (k2[8] + k3[8]) + k4[8]),
            x[9] + h6 * (k1[9] + 2.0 * (k2[9] + k3[9]) + k4[9]),
            x[10] + h6 * (k1[10] + 2.0 * (k2[10] + k3[10]) + k4[10]),
            x[11] + h6 * (k1[11] + 2.0 * (k2[11] + k3[11]) + k4[11]),
            x[12] + h6 * (k1[12] + 2.0 * (k2[12] + k3[12]) + k4[12]))


@njit
def _with_disturbance(pp: np.ndarray, dist: np.ndarray, r: tuple[float, ...],
                      t_s: float) -> tuple[float, ...]:
    if pp[_DIST_ACTIVE] == 0.0:
        return r
    f, t = disturbance_kernel(dist, t_s - pp[_DIST_T0])
    return (r[0] + f[0], r[1] + f[1], r[2] + f[2], r[3] + t[0], r[4] + t[1], r[5] + t[2])


@njit
def _wrench_after(pp: np.ndarray, speed0: np.ndarray, tilt0: np.ndarray, cmd: np.ndarray,
                  tau_s: float) -> tuple[float, ...]:
    """Rotor wrench on the exact (lagged) actuator trajectory tau_s into the step."""
    sp, ti = np.empty(6), np.empty(6)
    rotor_lag_kernel(pp[_WMAX], speed0, cmd[0:6], math.exp(-tau_s / pp[_TAU_UP]),
                     math.exp(-tau_s / pp[_TAU_DOWN]), sp)
    tilt_servo_kernel(tilt0, cmd[6:12], pp[_TILT_RATE] * tau_s, ti)
    return rotor_wrench_kernel(pp, sp, ti)


@njit
def step_kernel(pp: np.ndarray, dist: np.ndarray, s: np.ndarray, cmd: np.ndarray,
                out: np.ndarray) -> int:
    """Advance the state row s (STATE_SIZE) one step of dt_us with the command cmd (speeds,
    tilts) held, into out; returns the number of RK4 steps taken (one per smooth piece).

    A tilt servo that reaches its command inside the step has a kink in its trajectory at
    that instant; the step is then integrated piecewise, one RK4 step per sub-interval
    between kinks, so that every RK4 step sees a smooth actuator trajectory.
    """
    dt_us = pp[_DT_US]
    h = dt_us * 1e-6
    t0 = s[0] * 1e-6
    speed0, tilt0 = s[_SPEED:_TILT], s[_TILT:_LANDED]
    sp_end, ti_end = out[_SPEED:_TILT], out[_TILT:_LANDED]
    kinks = np.empty(6)
    n_kinks = 0
    w_max = pp[_WMAX]
    if pp[_IDEAL] != 0.0:
        for i in range(6):
            c = cmd[i]
            sp_end[i] = 0.0 if c < 0.0 else (w_max if c > w_max else c)
            ti_end[i] = cmd[6 + i]
        r0 = rotor_wrench_kernel(pp, sp_end, ti_end)
        r2 = r0
    else:
        rotor_lag_kernel(w_max, speed0, cmd[0:6], pp[_DECAY_UP], pp[_DECAY_DOWN], sp_end)
        rate = pp[_TILT_RATE]
        lim = rate * h
        for i in range(6):
            a0, c = tilt0[i], cmd[6 + i]
            d = c - a0
            if d > lim:
                ti_end[i] = a0 + lim
            elif d < -lim:
                ti_end[i] = a0 - lim
            else:
                ti_end[i] = c
                if d != 0.0:
                    t_k = abs(d) / rate
                    if t_k < h:  # t_k = h (to rounding) is the end of the step, no kink
                        kinks[n_kinks] = t_k
                        n_kinks += 1
        r0 = rotor_wrench_kernel(pp, speed0, tilt0)
        r2 = rotor_wrench_kernel(pp, sp_end, ti_end)
    w2 = _with_disturbance(pp, dist, r2, t0 + h)
    out[0] = s[0] + dt_us

    q = (s[7], s[8], s[9], s[10])
    if s[_LANDED] != 0.0 and pp[_GROUND] != 0.0:
        # Resting: stays unless the net vertical force lifts it off.
        fz_world = rotate(q, (w2[0], w2[1], w2[2]))[2] - pp[_MASS] * pp[_G]
        if fz_world <= 0.0:
            for j in range(1, 4):
                out[j] = s[j]
            for j in range(7, 11):
                out[j] = s[j]
            for j in (4, 5, 6, 11, 12, 13):
                out[j] = 0.0
            out[_LANDED] = 1.0
            return 0

    x = (s[1], s[2], s[3], s[4], s[5], s[6], s[7], s[8], s[9], s[10], s[11], s[12], s[13])
    w0 = _with_disturbance(pp, dist, r0, t0)
    pieces = 1
    if n_kinks == 0:
        # No kink inside the step: the actuator trajectory is smooth, one RK4 step.
        if pp[_IDEAL] != 0.0:
            r1 = r0
        else:
            sp_mid, ti_mid = np.empty(6), np.empty(6)
            rotor_lag_kernel(w_max, speed0, cmd[0:6], pp[_DECAY_HALF_UP],
                             pp[_DECAY_HALF_DOWN], sp_mid)
            tilt_servo_kernel(tilt0, cmd[6:12], 0.5 * pp[_TILT_RATE] * h, ti_mid)
            r1 = rotor_wrench_kernel(pp, sp_mid, ti_mid)
        y = _rk4(pp, x, h, w0, _with_disturbance(pp, dist, r1, t0 + 0.5 * h), w2)
    else:
        # Piecewise RK4 over [0, k_1], [k_1, k_2], ..., [k_n, h], k_j the kink instants;
        # the wrench at a sub-interval's end is the next one's start. In closed loop this
        # is frequent: a servo that keeps up with its command reaches each new one early
        # in the first physics step of the control period.
        ends = np.sort(kinks[:n_kinks])
        y, a, wa = x, 0.0, w0
        pieces = 0
        for j in range(n_kinks + 1):
            b = ends[j] if j < n_kinks else h
            if b <= a:
                continue  # servos reaching their commands at the same instant
            m = 0.5 * (a + b)
            wm = _with_disturbance(pp, dist, _wrench_after(pp, speed0, tilt0, cmd, m), t0 + m)
            wb = (w2 if b == h else
                  _with_disturbance(pp, dist, _wrench_after(pp, speed0, tilt0, cmd, b), t0 + b))
            y = _rk4(pp, y, b - a, wa, wm, wb)
            pieces += 1
            a, wa = b, wb
    qn = math.sqrt(y[6] * y[6] + y[7] * y[7] + y[8] * y[8] + y[9] * y[9])
    out[7], out[8], out[9], out[10] = y[6] / qn, y[7] / qn, y[8] / qn, y[9] / qn
    if pp[_GROUND] != 0.0 and y[2] < 0.0:
        out[1], out[2], out[3] = y[0], y[1], 0.0
        for j in (4, 5, 6, 11, 12, 13):
            out[j] = 0.0
        out[_LANDED] = 1.0
    else:
        for j in (1, 2, 3, 4, 5, 6):
            out[j] = y[j - 1]
        out[11], out[12], out[13] = y[10], y[11], y[12]
        out[_LANDED] = 0.0
    return pieces


@njit
def steps_kernel(pp: np.ndarray, dist: np.ndarray, s: np.ndarray, cmd: np.ndarray,
                 out: np.ndarray) -> None:
    """len(out) steps from the state row s under the held command: row k of out is the
    state after k + 1 steps."""
    step_kernel(pp, dist, s, cmd, out[0])
    for k in range(1, out.shape[0]):
        step_kernel(pp, dist, out[k - 1], cmd, out[k])


def state_row(s: PlantState) -> np.ndarray:
    """A PlantState as the kernels' state row (its truth row)."""
    return np.array(truth_row(s), dtype=np.float64)


def state_of_row(row: Sequence[float]) -> PlantState:
    """The PlantState of a state row (floats)."""
    return PlantState(int(row[0]), (row[1], row[2], row[3]), (row[4], row[5], row[6]),
                      (row[7], row[8], row[9], row[10]), (row[11], row[12], row[13]),
                      tuple(row[14:20]), tuple(row[20:26]), row[26] != 0.0)


class Plant:
    """Fixed-step simulator; `step` is a pure function of (state, command)."""

    def __init__(self, vehicle: VehicleConfig, *, dt_us: int = 1000,
                 ideal_actuators: bool = False, ground_enabled: bool = True,
                 disturbance: Disturbance | None = None) -> None:
        if dt_us <= 0:
            raise ValueError("dt_us must be positive")
        self.vehicle = vehicle
        self.dt_us = dt_us
        self.ideal = ideal_actuators
        self.ground = ground_enabled
        self.mass = vehicle.mass_kg
        self.inertia = vehicle.inertia_diag_kg_m2
        self.g = vehicle.gravity_m_s2
        self.w_max = vehicle.rotor_speed_max_rad_s
        self.tau_up = vehicle.rotor_tau_up_s
        self.tau_down = vehicle.rotor_tau_down_s
        self.tilt_rate = vehicle.tilt_rate_max_rad_s
        cf, cd = vehicle.thrust_coeff, vehicle.drag_coeff
        rotors = []
        for fr in rotor_frames(vehicle):
            ev, el, r = fr.e_v_flu, fr.e_l_flu, fr.r_flu_m
            # force and torque per unit w^2 for thrust along e_v and along e_l
            fv = tuple(cf * c for c in ev)
            fl = tuple(cf * c for c in el)
            tv = _moment(r, fv, fr.spin * cd, ev)
            tl = _moment(r, fl, fr.spin * cd, el)
            rotors.append((*fv, *fl, *tv, *tl))
        self._rotors = tuple(rotors)
        h = dt_us * 1e-6
        pp = np.zeros(PARAMS_SIZE)
        pp[:_IDEAL] = (self.mass, *self.inertia, self.g, self.w_max, self.tau_up,
                       self.tau_down, self.tilt_rate, float(dt_us))
        pp[_IDEAL:_DIST_ACTIVE] = (float(self.ideal), float(self.ground),
                                   math.exp(-h / self.tau_up), math.exp(-h / self.tau_down),
                                   math.exp(-0.5 * h / self.tau_up),
                                   math.exp(-0.5 * h / self.tau_down))
        pp[_ROTORS:] = [c for rotor in rotors for c in rotor]
        self.params = pp
        self.disturbance = disturbance or Disturbance()
        self.last_rk4_steps = 0  # RK4 steps of the last `step` (one per smooth piece)
        warm_up("sitl.plant", self._warm_up)

    def _warm_up(self) -> None:
        """Two steps at rest in the air (compiles or loads the step kernels before the
        first control period)."""
        row = state_row(self.initial_state((0.0, 0.0, 1.0), on_ground=False))
        self.step_rows(row, np.zeros(12), np.empty((2, STATE_SIZE)))
        step_kernel(self.params, self._disturbance.table, row, np.zeros(12),
                    np.empty(STATE_SIZE))

    @property
    def disturbance(self) -> Disturbance:
        return self._disturbance

    @disturbance.setter
    def disturbance(self, d: Disturbance) -> None:
        self._disturbance = d
        self.params[_DIST_ACTIVE] = 1.0 if d.active else 0.0
        self.params[_DIST_T0] = d.t0_s

    # ------------------------------------------------------------------ actuators

    def actuators_at(self, speed0: tuple[float, ...], tilt0: tuple[float, ...],
                     cmd: ActuatorCommand, tau_s: float) -> tuple[list[float], list[float]]:
        """Exact rotor speeds and tilts tau_s after (speed0, tilt0) under a held command."""
        if self.ideal:
            w_max = self.w_max
            return ([0.0 if c < 0.0 else (w_max if c > w_max else c)
                     for c in cmd.rotor_speed_rad_s], list(cmd.tilt_rad))
        decay_up, decay_down = math.exp(-tau_s / self.tau_up), math.exp(-tau_s / self.tau_down)
        return (self._rotor_lag(speed0, cmd.rotor_speed_rad_s, decay_up, decay_down),
                self._tilt_servo(tilt0, cmd.tilt_rad, self.tilt_rate * tau_s))

    def _rotor_lag(self, speed0: Sequence[float], cmd: Sequence[float], decay_up: float,
                   decay_down: float) -> list[float]:
        """First-order lag towards the command clamped to [0, w_max], exact over the hold."""
        n = len(speed0)  # any number of rotors (tests drive a single one)
        out = np.empty(n)
        rotor_lag_kernel(self.w_max, _f64(speed0, n), _f64(cmd, n), float(decay_up),
                         float(decay_down), out)
        return list(out.tolist())

    @staticmethod
    def _tilt_servo(tilt0: Sequence[float], cmd: Sequence[float], lim: float) -> list[float]:
        """Rate-limited servo: moves towards the command by at most `lim`."""
        n = len(tilt0)
        out = np.empty(n)
        tilt_servo_kernel(_f64(tilt0, n), _f64(cmd, n), float(lim), out)
        return list(out.tolist())

    def rotor_wrench(self, speeds: Sequence[float],
                     tilts: Sequence[float]) -> tuple[Vec3, Vec3]:
        """Sum over rotors of thrust and torque (arm moment plus drag), in FLU."""
        r = rotor_wrench_kernel(self.params, _f64(speeds, 6), _f64(tilts, 6))
        return (r[0], r[1], r[2]), (r[3], r[4], r[5])

    # ------------------------------------------------------------------ rigid body

    def derivative(self, x: Sequence[float], wrench: Sequence[float]) -> tuple[float, ...]:
        """d/dt of (p, v, q, w) in ENU/FLU under a body wrench (f, tau)."""
        return derivative_kernel(self.params, tuple(float(c) for c in x),
                                 tuple(float(c) for c in wrench))

    def step(self, s: PlantState, cmd: ActuatorCommand) -> PlantState:
        """Advance one step of dt_us with the command held (zero-order hold); see
        `step_kernel`."""
        out = np.empty(STATE_SIZE)
        self.last_rk4_steps = step_kernel(self.params, self._disturbance.table, state_row(s),
                                          command_row(cmd), out)
        return state_of_row(out.tolist())

    def step_rows(self, row: np.ndarray, cmd: np.ndarray, out: np.ndarray) -> None:
        """len(out) steps from the state row `row` under the command row `cmd` (speeds,
        tilts: 12 floats) held, into the rows of `out` (the state after each step)."""
        steps_kernel(self.params, self._disturbance.table, row, cmd, out)

    # ------------------------------------------------------------------ helpers

    def initial_state(self, p_enu_m: Vec3, *, on_ground: bool,
                      rotor_speed_rad_s: tuple[float, ...] | None = None,
                      tilt_rad: tuple[float, ...] | None = None,
                      q_enu_flu: Quat = (1.0, 0.0, 0.0, 0.0)) -> PlantState:
        n = self.vehicle.n_rotors
        return PlantState(0, p_enu_m, (0.0, 0.0, 0.0), q_enu_flu, (0.0, 0.0, 0.0),
                          tuple(rotor_speed_rad_s or (0.0,) * n), tuple(tilt_rad or (0.0,) * n),
                          on_ground and self.ground)

    def specific_force_flu(self, s: PlantState) -> Vec3:
        """What an accelerometer at the CoM reads: (R^T (a - g_W)) = f_b / m."""
        if s.landed:
            return rotate_inv(s.q_enu_flu, (0.0, 0.0, self.g))
        r = rotor_wrench_kernel(self.params, _f64(s.rotor_speed_rad_s, 6),
                                _f64(s.tilt_rad, 6))
        w = _with_disturbance(self.params, self._disturbance.table, r, s.time_us * 1e-6)
        return (w[0] / self.mass, w[1] / self.mass, w[2] / self.mass)

    def energy(self, s: PlantState) -> float:
        """Kinetic plus potential energy (for conservation tests)."""
        jx, jy, jz = self.inertia
        w, v = s.omega_flu_rad_s, s.v_enu_m_s
        return (0.5 * self.mass * (v[0] ** 2 + v[1] ** 2 + v[2] ** 2)
                + 0.5 * (jx * w[0] ** 2 + jy * w[1] ** 2 + jz * w[2] ** 2)
                + self.mass * self.g * s.p_enu_m[2])


def _f64(values: Sequence[float], n: int) -> np.ndarray:
    a = np.asarray(values, dtype=np.float64)
    if a.shape != (n,):
        raise ValueError(f"expected {n} values, got {a.shape}")
    return a


def command_row(cmd: ActuatorCommand) -> np.ndarray:
    """An ActuatorCommand as the kernels' command row (speeds, tilts)."""
    return np.array((*cmd.rotor_speed_rad_s, *cmd.tilt_rad), dtype=np.float64)


def _moment(r: Vec3, f: tuple[float, ...], spin_cd: float, e: Vec3) -> tuple[float, ...]:
    """r x f - sigma c_d e: arm moment of the thrust plus the rotor's drag torque."""
    return (r[1] * f[2] - r[2] * f[1] - spin_cd * e[0],
            r[2] * f[0] - r[0] * f[2] - spin_cd * e[1],
            r[0] * f[1] - r[1] * f[0] - spin_cd * e[2])


def hover_speeds_and_tilts(plant: Plant) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Equal rotor speeds at zero tilt that carry the weight (the plant's own solution; the
    minimum-norm allocation of both presets, MODEL.md section 2)."""
    n = plant.vehicle.n_rotors
    (_, _, fz), _ = plant.rotor_wrench([1.0] * n, [0.0] * n)
    w = math.sqrt(plant.mass * plant.g / fz)
    return (w,) * n, (0.0,) * n


def scenario_plant(scenario: Scenario, dt_us: int) -> Plant:
    """The scenario's plant (vehicle, actuators, ground, disturbances) at a step of dt_us."""
    return Plant(scenario.vehicle, dt_us=dt_us, ideal_actuators=scenario.ideal_actuators,
                 ground_enabled=scenario.ground_enabled,
                 disturbance=Disturbance(scenario.force_terms, scenario.torque_terms))


def initial_state(scenario: Scenario, plant: Plant) -> PlantState:
    """Resting on the ground with rotors stopped, or airborne in hover (MODEL.md 5)."""
    if scenario.start == "ground":
        return plant.initial_state(scenario.initial_position_enu_m, on_ground=True)
    speeds, tilts = hover_speeds_and_tilts(plant)
    return plant.initial_state(scenario.initial_position_enu_m, on_ground=False,
                               rotor_speed_rad_s=speeds, tilt_rad=tilts)
