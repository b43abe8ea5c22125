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
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

from common.config import Scenario, VehicleConfig
from common.geometry import rotor_frames
from sitl.disturbance import Disturbance

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


def rotate(q: Quat, v: Vec3) -> Vec3:
    """R(q) v via the rotation matrix of q (the controller uses another formula)."""
    w, x, y, z = q
    vx, vy, vz = v
    return ((1 - 2 * (y * y + z * z)) * vx + 2 * (x * y - w * z) * vy + 2 * (x * z + w * y) * vz,
            2 * (x * y + w * z) * vx + (1 - 2 * (x * x + z * z)) * vy + 2 * (y * z - w * x) * vz,
            2 * (x * z - w * y) * vx + 2 * (y * z + w * x) * vy + (1 - 2 * (x * x + y * y)) * vz)


def rotate_inv(q: Quat, v: Vec3) -> Vec3:
    return rotate((q[0], -q[1], -q[2], -q[3]), v)


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
        self.disturbance = disturbance or Disturbance()
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
        self._decay_up, self._decay_down = math.exp(-h / self.tau_up), math.exp(-h / self.tau_down)
        self._decay_half_up = math.exp(-0.5 * h / self.tau_up)
        self._decay_half_down = math.exp(-0.5 * h / self.tau_down)
        self._last_key: tuple[tuple[float, ...], tuple[float, ...]] | None = None
        self._last_wrench: tuple[float, ...] = (0.0,) * 6

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
        w_max = self.w_max
        out = []
        for w0, c in zip(speed0, cmd, strict=True):
            c = 0.0 if c < 0.0 else (w_max if c > w_max else c)
            out.append(c + (w0 - c) * (decay_up if c > w0 else decay_down))
        return out

    @staticmethod
    def _tilt_servo(tilt0: Sequence[float], cmd: Sequence[float], lim: float) -> list[float]:
        """Rate-limited servo: moves towards the command by at most `lim` (and lands on it
        exactly, so that a servo at rest has no kink in the next step)."""
        out = []
        for a0, c in zip(tilt0, cmd, strict=True):
            d = c - a0
            out.append(a0 + lim if d > lim else (a0 - lim if d < -lim else c))
        return out

    @staticmethod
    def _tilt_servo_kinks(tilt0: Sequence[float], cmd: Sequence[float], rate: float, h: float,
                          kinks: list[float]) -> list[float]:
        """`_tilt_servo` over a step of h, appending to `kinks` each instant in (0, h) where a
        servo reaches its command (its trajectory a0 + clamp(c - a0, -rate t, rate t) has a
        kink there)."""
        lim = rate * h
        out = []
        for a0, c in zip(tilt0, cmd, strict=True):
            d = c - a0
            if d > lim:
                out.append(a0 + lim)
            elif d < -lim:
                out.append(a0 - lim)
            else:
                out.append(c)
                if d != 0.0:
                    t_k = abs(d) / rate
                    if t_k < h:  # t_k = h (to rounding) is the end of the step, no kink
                        kinks.append(t_k)
        return out

    def rotor_wrench(self, speeds: Sequence[float],
                     tilts: Sequence[float]) -> tuple[Vec3, Vec3]:
        """Sum over rotors of thrust and torque (arm moment plus drag), in FLU."""
        fx = fy = fz = tx = ty = tz = 0.0
        for (fvx, fvy, fvz, flx, fly, flz, tvx, tvy, tvz, tlx, tly, tlz), w, a in zip(
                self._rotors, speeds, tilts, strict=True):
            w2 = w * w
            c = w2 * math.cos(a)
            s = w2 * math.sin(a)
            fx += c * fvx + s * flx
            fy += c * fvy + s * fly
            fz += c * fvz + s * flz
            tx += c * tvx + s * tlx
            ty += c * tvy + s * tly
            tz += c * tvz + s * tlz
        return (fx, fy, fz), (tx, ty, tz)

    # ------------------------------------------------------------------ rigid body

    def derivative(self, x: Sequence[float], wrench: Sequence[float]) -> tuple[float, ...]:
        """d/dt of (p, v, q, w) in ENU/FLU under a body wrench (f, tau)."""
        _, _, _, vx, vy, vz, qw, qx, qy, qz, wx, wy, wz = x
        fx, fy, fz, tx, ty, tz = wrench
        inv_m = 1.0 / self.mass
        ax, ay, az = rotate((qw, qx, qy, qz), (fx * inv_m, fy * inv_m, fz * inv_m))
        jx, jy, jz = self.inertia
        return (vx, vy, vz,
                ax, ay, az - self.g,
                0.5 * (-qx * wx - qy * wy - qz * wz),
                0.5 * (qw * wx + qy * wz - qz * wy),
                0.5 * (qw * wy - qx * wz + qz * wx),
                0.5 * (qw * wz + qx * wy - qy * wx),
                (tx - (jz - jy) * wy * wz) / jx,
                (ty - (jx - jz) * wz * wx) / jy,
                (tz - (jy - jx) * wx * wy) / jz)

    def step(self, s: PlantState, cmd: ActuatorCommand) -> PlantState:
        """Advance one step of dt_us with the command held (zero-order hold).

        A tilt servo that reaches its command inside the step has a kink in its trajectory at
        that instant; the step is then integrated piecewise, one RK4 step per sub-interval
        between kinks, so that every RK4 step sees a smooth actuator trajectory.
        """
        h = self.dt_us * 1e-6
        t0 = s.time_us * 1e-6
        kinks: list[float] = []
        if self.ideal:
            sp_end, ti_end = self.actuators_at(s.rotor_speed_rad_s, s.tilt_rad, cmd, h)
            r0 = r2 = self._cached_rotor_wrench(sp_end, ti_end)
        else:
            sp_end = self._rotor_lag(s.rotor_speed_rad_s, cmd.rotor_speed_rad_s,
                                     self._decay_up, self._decay_down)
            ti_end = self._tilt_servo_kinks(s.tilt_rad, cmd.tilt_rad, self.tilt_rate, h, kinks)
            # Start before end: the end of this step is the start of the next (memoised).
            r0 = self._cached_rotor_wrench(s.rotor_speed_rad_s, s.tilt_rad)
            r2 = self._cached_rotor_wrench(sp_end, ti_end)
        w2 = self._with_disturbance(r2, t0 + h)

        time_us = s.time_us + self.dt_us
        actuators = (tuple(sp_end), tuple(ti_end))

        if s.landed and self.ground:
            # Resting: stays unless the net vertical force lifts it off.
            fz_world = rotate(s.q_enu_flu, (w2[0], w2[1], w2[2]))[2] - self.mass * self.g
            if fz_world <= 0.0:
                return PlantState(time_us, s.p_enu_m, (0.0, 0.0, 0.0), s.q_enu_flu,
                                  (0.0, 0.0, 0.0), *actuators, True)

        x: list[float] = [*s.p_enu_m, *s.v_enu_m_s, *s.q_enu_flu, *s.omega_flu_rad_s]
        w0 = self._with_disturbance(r0, t0)
        if not kinks:
            # No kink inside the step: the actuator trajectory is smooth, one RK4 step.
            if self.ideal:
                r1 = r0
            else:
                sp_mid = self._rotor_lag(s.rotor_speed_rad_s, cmd.rotor_speed_rad_s,
                                         self._decay_half_up, self._decay_half_down)
                ti_mid = self._tilt_servo(s.tilt_rad, cmd.tilt_rad, 0.5 * self.tilt_rate * h)
                r1 = self._rotor_wrench6(sp_mid, ti_mid)
            y = self._rk4(x, h, w0, self._with_disturbance(r1, t0 + 0.5 * h), w2)
        else:
            # Piecewise RK4 over [0, k_1], [k_1, k_2], ..., [k_n, h], k_j the kink instants;
            # the wrench at a sub-interval's end is the next one's start. In closed loop this
            # is frequent: a servo that keeps up with its command reaches each new one early
            # in the first physics step of the control period.
            kinks.sort()
            y, a, wa = x, 0.0, w0
            for b in (*kinks, h):
                if b <= a:
                    continue  # servos reaching their commands at the same instant
                m = 0.5 * (a + b)
                wm = self._with_disturbance(self._wrench_after(s, cmd, m), t0 + m)
                wb = (w2 if b == h else
                      self._with_disturbance(self._wrench_after(s, cmd, b), t0 + b))
                y = self._rk4(y, b - a, wa, wm, wb)
                a, wa = b, wb
        qn = math.sqrt(y[6] * y[6] + y[7] * y[7] + y[8] * y[8] + y[9] * y[9])
        q = (y[6] / qn, y[7] / qn, y[8] / qn, y[9] / qn)
        p, v, w = (y[0], y[1], y[2]), (y[3], y[4], y[5]), (y[10], y[11], y[12])
        landed = False
        if self.ground and p[2] < 0.0:
            p, v, w, landed = (p[0], p[1], 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), True
        return PlantState(time_us, p, v, q, w, *actuators, landed)

    def _rk4(self, x: Sequence[float], h: float, wa: tuple[float, ...], wm: tuple[float, ...],
             wb: tuple[float, ...]) -> list[float]:
        """One classical RK4 step of length h; wrench at the start, midpoint and end."""
        derivative = self.derivative
        hh = 0.5 * h
        k1 = derivative(x, wa)
        k2 = derivative(_axpy(x, hh, k1), wm)
        k3 = derivative(_axpy(x, hh, k2), wm)
        k4 = derivative(_axpy(x, h, k3), wb)
        h6 = h / 6.0
        return [a + h6 * (b + 2.0 * (c + d) + e)
                for a, b, c, d, e in zip(x, k1, k2, k3, k4, strict=True)]

    def _wrench_after(self, s: PlantState, cmd: ActuatorCommand,
                      tau_s: float) -> tuple[float, ...]:
        """Rotor wrench on the exact actuator trajectory tau_s into the step from s."""
        f, t = self.rotor_wrench(*self.actuators_at(s.rotor_speed_rad_s, s.tilt_rad, cmd,
                                                    tau_s))
        return (*f, *t)

    def _rotor_wrench6(self, speeds: Sequence[float], tilts: Sequence[float]) -> tuple[float, ...]:
        f, t = self.rotor_wrench(speeds, tilts)
        return (*f, *t)

    def _cached_rotor_wrench(self, speeds: Sequence[float],
                             tilts: Sequence[float]) -> tuple[float, ...]:
        """rotor_wrench memoised on the last actuator state: a step's end is the next start."""
        key = (tuple(speeds), tuple(tilts))
        if key != self._last_key:
            self._last_key = key
            f, t = self.rotor_wrench(speeds, tilts)
            self._last_wrench = (*f, *t)
        return self._last_wrench

    def _with_disturbance(self, rotor: tuple[float, ...], t_s: float) -> tuple[float, ...]:
        if not self.disturbance.active:
            return rotor
        (dfx, dfy, dfz), (dtx, dty, dtz) = self.disturbance.wrench(t_s)
        return (rotor[0] + dfx, rotor[1] + dfy, rotor[2] + dfz,
                rotor[3] + dtx, rotor[4] + dty, rotor[5] + dtz)

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
        f, t = self.rotor_wrench(s.rotor_speed_rad_s, s.tilt_rad)
        w = self._with_disturbance((*f, *t), s.time_us * 1e-6)
        if s.landed:
            return rotate_inv(s.q_enu_flu, (0.0, 0.0, self.g))
        return (w[0] / self.mass, w[1] / self.mass, w[2] / self.mass)

    def energy(self, s: PlantState) -> float:
        """Kinetic plus potential energy (for conservation tests)."""
        jx, jy, jz = self.inertia
        w, v = s.omega_flu_rad_s, s.v_enu_m_s
        return (0.5 * self.mass * (v[0] ** 2 + v[1] ** 2 + v[2] ** 2)
                + 0.5 * (jx * w[0] ** 2 + jy * w[1] ** 2 + jz * w[2] ** 2)
                + self.mass * self.g * s.p_enu_m[2])


def _axpy(x: Sequence[float], h: float, k: Sequence[float]) -> tuple[float, ...]:
    """x + h k for the 13 rigid-body states (unrolled: three times per RK4 step)."""
    x0, x1, x2, x3, x4, x5, x6, x7, x8, x9, x10, x11, x12 = x
    k0, k1, k2, k3, k4, k5, k6, k7, k8, k9, k10, k11, k12 = k
    return (x0 + h * k0, x1 + h * k1, x2 + h * k2, x3 + h * k3, x4 + h * k4, x5 + h * k5,
            x6 + h * k6, x7 + h * k7, x8 + h * k8, x9 + h * k9, x10 + h * k10, x11 + h * k11,
            x12 + h * k12)


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


def initial_state(scenario: Scenario, plant: Plant) -> PlantState:
    """Resting on the ground with rotors stopped, or airborne in hover (MODEL.md 5)."""
    if scenario.start == "ground":
        return plant.initial_state(scenario.initial_position_enu_m, on_ground=True)
    speeds, tilts = hover_speeds_and_tilts(plant)
    return plant.initial_state(scenario.initial_position_enu_m, on_ground=False,
                               rotor_speed_rad_s=speeds, tilt_rad=tilts)
