"""Rigid-body plant of a tilt-rotor multirotor with rotor and tilt-servo dynamics.

Independent of the controller on purpose (no dual quaternions, no allocation matrix): the
world-frame Newton-Euler equations in ENU/FLU with gravity,
    p' = v,   m v' = R(q) f_b + m g_W,   q' = 1/2 q (0, w),   J w' = tau_b - w x J w,
integrated by fixed-step RK4 with the quaternion renormalised after each step. The rotor
wrench is the per-rotor sum F_i = c_f w_i^2 n_i, Q_i = -sigma_i c_d w_i^2 n_i
(docs/model.md#geometry).

Actuators are decoupled from the body, so their state inside a step is known in closed form:
a first-order rotor lag (time constants up/down) towards a command clamped to [0, w_max], and
a rate-limited tilt servo, tilt(t) = a0 + clamp(c - a0, -rate t, rate t). The wrench is
evaluated on that exact actuator trajectory at the RK4 stage times. A servo that reaches its
command inside a step puts a kink in the trajectory at t = |c - a0| / rate; the step is then
split at every such instant and integrated piecewise, so that no RK4 step straddles a kink and
the actuator trajectory stays exact. `ideal_actuators` makes both follow their commands
instantly (the speed limits stay: they are physical).

Ground (z = 0): a resting vehicle stays put while the net vertical force does not lift it;
a vehicle reaching z < 0 stops there (inelastic contact, velocities zeroed). What an
accelerometer reads (`specific_force_flu`) includes the ground's force: the normal reaction
while resting, and in the physics step of a touchdown the contact's impulse, the velocity
change it imposed divided by the step (`contact_dv_enu`), so that the reported specific
force plus gravity integrates to the true velocity change.

The step is a compiled kernel (`sitl.plant_kernels.step_kernel`, numba) on a flat state
array laid out as TRUTH_COLUMNS (so a state is its truth-log row) and a flat parameter array
(sitl.layouts: PLANT_STATE, PLANT_PARAMS); `Plant.step` is its Python face on PlantState,
`Plant.step_rows` runs a control period's substeps at once. The plant's own rotation
(`rotate`, `rotate_inv`, independent of the controller's) is part of this module's interface.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from common.config.scenario import Scenario, VehicleConfig
from common.geometry import rotor_frames
from common.jit import compiled_for
from common.logs.columns import TRUTH_COLUMNS
from common.vehicle_constants import N_ROTORS
from common.warm_ups import warm_up
from sitl.disturbance import Disturbance
from sitl.layouts import (
    PC_SIZE,
    PLANT_COMMAND,
    PLANT_STATE,
    PP_DECAY_DOWN,
    PP_DECAY_HALF_DOWN,
    PP_DECAY_HALF_UP,
    PP_DECAY_UP,
    PP_DIST_ACTIVE,
    PP_DIST_T0,
    PP_DT_US,
    PP_G,
    PP_GROUND,
    PP_IDEAL,
    PP_J,
    PP_MASS,
    PP_ROTORS,
    PP_SIZE,
    PP_TAU_DOWN,
    PP_TAU_UP,
    PP_TILT_RATE,
    PP_WMAX,
    PR_F_L,
    PR_F_V,
    PR_SIZE,
    PR_TAU_L,
    PR_TAU_V,
    PS_LANDED,
    PS_P,
    PS_Q,
    PS_SIZE,
    PS_SPEED,
    PS_TILT,
    PS_TIME,
    PS_V,
    PS_W,
)
from sitl.plant_kernels import (
    flight_force_kernel,
    rotor_lag_kernel,
    rotor_wrench_kernel,
    step_kernel,
    steps_kernel,
    tilt_servo_kernel,
)
from sitl.plant_kernels import rotate as rotate
from sitl.plant_kernels import rotate_inv as rotate_inv

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


STATE_SIZE = PS_SIZE  # the kernels' state row: a truth row
assert len(TRUTH_COLUMNS) == STATE_SIZE and PLANT_STATE.at("landed") == STATE_SIZE - 1
PARAMS_SIZE = PP_SIZE


def truth_row(s: PlantState) -> tuple[float, ...]:
    """One row of the ground-truth log (ENU/FLU, SI units; TRUTH_COLUMNS)."""
    return (s.time_us, *s.p_enu_m, *s.v_enu_m_s, *s.q_enu_flu, *s.omega_flu_rad_s,
            *s.rotor_speed_rad_s, *s.tilt_rad, float(s.landed))


class ActuatorCommand(NamedTuple):
    rotor_speed_rad_s: tuple[float, ...]
    tilt_rad: tuple[float, ...]


# The kernels' rows hold these tuples' fields in order (truth_row, command_row).
assert PLANT_STATE.names() == PlantState._fields
assert PLANT_COMMAND.names() == ActuatorCommand._fields


def state_row(s: PlantState) -> np.ndarray:
    """A PlantState as the kernels' state row (its truth row)."""
    return np.array(truth_row(s), dtype=np.float64)


def state_of_row(row: Sequence[float]) -> PlantState:
    """The PlantState of a state row (floats)."""
    p, v, q, w = PS_P, PS_V, PS_Q, PS_W
    return PlantState(int(row[PS_TIME]), (row[p], row[p + 1], row[p + 2]),
                      (row[v], row[v + 1], row[v + 2]),
                      (row[q], row[q + 1], row[q + 2], row[q + 3]),
                      (row[w], row[w + 1], row[w + 2]),
                      tuple(row[PS_SPEED:PS_SPEED + N_ROTORS]),
                      tuple(row[PS_TILT:PS_TILT + N_ROTORS]), row[PS_LANDED] != 0.0)


class ContactImpulses:
    """The ground contact's velocity changes (`Plant.contact_dv_enu`, ENU m/s) summed until
    an accelerometer sample takes them."""

    def __init__(self) -> None:
        self._dv: Vec3 = (0.0, 0.0, 0.0)

    def add(self, dv_enu: Vec3) -> None:
        c = self._dv
        self._dv = (c[0] + dv_enu[0], c[1] + dv_enu[1], c[2] + dv_enu[2])

    def take(self) -> Vec3:
        """The sum since the last take, and start again from zero."""
        dv, self._dv = self._dv, (0.0, 0.0, 0.0)
        return dv


class ContactSpread:
    """Touchdown impulses spread evenly over `spread_us` from the sample they came in (a
    landing gear's compliance stretches a real touchdown's deceleration over tens of
    milliseconds): `take(dv, dt_us)` is the part that falls in a sample of dt_us; the parts
    sum to each impulse. 0: each impulse all in its own sample."""

    def __init__(self, spread_us: int) -> None:
        self.spread_us = spread_us
        self._spreading: list[tuple[Vec3, int]] = []  # [impulse, us still to report]

    def take(self, dv: Vec3, dt_us: int) -> Vec3:
        if self.spread_us <= 0:
            return dv
        if dv != (0.0, 0.0, 0.0):
            self._spreading.append((dv, self.spread_us))
        elif not self._spreading:
            return (0.0, 0.0, 0.0)
        out = [0.0, 0.0, 0.0]
        left = []
        for whole, rest_us in self._spreading:
            part = min(dt_us, rest_us) / self.spread_us
            for i in range(3):
                out[i] += whole[i] * part
            if rest_us > dt_us:
                left.append((whole, rest_us - dt_us))
        self._spreading = left
        return (out[0], out[1], out[2])


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
        h = dt_us * 1e-6
        pp = np.zeros(PARAMS_SIZE)
        pp[PP_MASS], pp[PP_J:PP_J + 3], pp[PP_G] = self.mass, self.inertia, self.g
        pp[PP_WMAX], pp[PP_TAU_UP], pp[PP_TAU_DOWN] = self.w_max, self.tau_up, self.tau_down
        pp[PP_TILT_RATE], pp[PP_DT_US] = self.tilt_rate, float(dt_us)
        pp[PP_IDEAL], pp[PP_GROUND] = float(self.ideal), float(self.ground)
        pp[PP_DECAY_UP] = math.exp(-h / self.tau_up)
        pp[PP_DECAY_DOWN] = math.exp(-h / self.tau_down)
        pp[PP_DECAY_HALF_UP] = math.exp(-0.5 * h / self.tau_up)
        pp[PP_DECAY_HALF_DOWN] = math.exp(-0.5 * h / self.tau_down)
        for i, fr in enumerate(rotor_frames(vehicle)):
            ev, el, r = fr.e_v_flu, fr.e_l_flu, fr.r_flu_m
            # force and torque per unit w^2 for thrust along e_v and along e_l
            fv = tuple(cf * c for c in ev)
            fl = tuple(cf * c for c in el)
            at = PP_ROTORS + PR_SIZE * i
            pp[at + PR_F_V:at + PR_F_V + 3] = fv
            pp[at + PR_F_L:at + PR_F_L + 3] = fl
            pp[at + PR_TAU_V:at + PR_TAU_V + 3] = _moment(r, fv, fr.spin * cd, ev)
            pp[at + PR_TAU_L:at + PR_TAU_L + 3] = _moment(r, fl, fr.spin * cd, el)
        self.params = pp
        self.disturbance = disturbance or Disturbance()
        self.last_rk4_steps = 0  # RK4 steps of the last `step` (one per smooth piece)
        warm_up("sitl.plant", self._warm_up)
        # the kernel's machine code for its arrays' types (`compiled_for`; loaded by the
        # warm-up, which the programs time and count in compile_time_s)
        self._steps = compiled_for(steps_kernel, pp, self._disturbance.table,
                                   np.empty(STATE_SIZE), np.empty(PC_SIZE),
                                   np.empty((2, STATE_SIZE)))

    def _warm_up(self) -> None:
        """Two steps at rest in the air (compiles or loads the step kernels before the
        first control period)."""
        row = state_row(self.initial_state((0.0, 0.0, 1.0), on_ground=False))
        steps_kernel(self.params, self._disturbance.table, row, np.zeros(PC_SIZE),
                     np.empty((2, STATE_SIZE)))
        step_kernel(self.params, self._disturbance.table, row, np.zeros(PC_SIZE),
                    np.empty(STATE_SIZE))
        flight_force_kernel(self.params, self._disturbance.table, np.zeros(2 * N_ROTORS),
                            0.0, self.mass)

    @property
    def disturbance(self) -> Disturbance:
        return self._disturbance

    @disturbance.setter
    def disturbance(self, d: Disturbance) -> None:
        self._disturbance = d
        self.params[PP_DIST_ACTIVE] = 1.0 if d.active else 0.0
        self.params[PP_DIST_T0] = d.t0_s

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
        r = rotor_wrench_kernel(self.params, _f64(speeds, N_ROTORS), _f64(tilts, N_ROTORS))
        return (r[0], r[1], r[2]), (r[3], r[4], r[5])

    # ------------------------------------------------------------------ rigid body

    def step(self, s: PlantState, cmd: ActuatorCommand) -> PlantState:
        """Advance one step of dt_us with the command held (zero-order hold); see
        `step_kernel`."""
        out = np.empty(STATE_SIZE)
        self.last_rk4_steps = step_kernel(self.params, self._disturbance.table, state_row(s),
                                          command_row(cmd), out)
        return state_of_row(out.tolist())

    def step_rows(self, row: np.ndarray, cmd: np.ndarray, out: np.ndarray) -> None:
        """len(out) steps from the state row `row` under the command row `cmd` (speeds,
        tilts: PLANT_COMMAND) held, into the rows of `out` (the state after each step): all
        float64 and C-contiguous, `out` two-dimensional (`compiled_for`)."""
        self._steps(self.params, self._disturbance.table, row, cmd, out)

    # ------------------------------------------------------------------ helpers

    def initial_state(self, p_enu_m: Vec3, *, on_ground: bool,
                      rotor_speed_rad_s: tuple[float, ...] | None = None,
                      tilt_rad: tuple[float, ...] | None = None,
                      q_enu_flu: Quat = (1.0, 0.0, 0.0, 0.0)) -> PlantState:
        n = self.vehicle.n_rotors
        return PlantState(0, p_enu_m, (0.0, 0.0, 0.0), q_enu_flu, (0.0, 0.0, 0.0),
                          tuple(rotor_speed_rad_s or (0.0,) * n), tuple(tilt_rad or (0.0,) * n),
                          on_ground and self.ground)

    def contact_dv_enu(self, prev: PlantState, s: PlantState) -> Vec3:
        """The velocity change the inelastic ground contact imposed in the physics step from
        `prev` to `s` (one step apart): the step ended resting from flight (v_s - v_prev =
        -v_prev); zero in every other step."""
        if not s.landed or prev.landed:
            return (0.0, 0.0, 0.0)
        v0, v1 = prev.v_enu_m_s, s.v_enu_m_s
        return (v1[0] - v0[0], v1[1] - v0[1], v1[2] - v0[2])

    def specific_force_flu(self, s: PlantState, prev: PlantState | None = None, *,
                           contact_dv_enu: Vec3 | None = None,
                           interval_s: float | None = None) -> Vec3:
        """What an accelerometer at the CoM reads at s, R^T (a - g_W): the rotor and
        disturbance force per mass in flight, the normal reaction (R^T g up) resting, plus
        a contact impulse per mass, dv / interval: the step's from `prev` (the state one
        physics step before s) by default, or `contact_dv_enu` spread over `interval_s`
        (an IMU sample's interval that holds the touchdown's step; default the step)."""
        if contact_dv_enu is None:
            contact_dv_enu = (0.0, 0.0, 0.0) if prev is None else \
                self.contact_dv_enu(prev, s)
        if s.landed:
            f: Vec3 = rotate_inv(s.q_enu_flu, (0.0, 0.0, self.g))
        else:
            actuators = np.array((*s.rotor_speed_rad_s, *s.tilt_rad), dtype=np.float64)
            if actuators.shape != (2 * N_ROTORS,):
                raise ValueError(f"expected {N_ROTORS} rotor speeds and tilts, got "
                                 f"{len(s.rotor_speed_rad_s)} and {len(s.tilt_rad)}")
            f = flight_force_kernel(self.params, self._disturbance.table, actuators,
                                    s.time_us * 1e-6, self.mass)
        if contact_dv_enu == (0.0, 0.0, 0.0):
            return f
        h = self.dt_us * 1e-6 if interval_s is None else interval_s
        j = rotate_inv(s.q_enu_flu, (contact_dv_enu[0] / h, contact_dv_enu[1] / h,
                                     contact_dv_enu[2] / h))
        return (f[0] + j[0], f[1] + j[1], f[2] + j[2])

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
    minimum-norm allocation of both presets, docs/model.md#geometry)."""
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
    """Resting on the ground with rotors stopped, or airborne in hover (docs/model.md#scenarios)."""
    if scenario.start == "ground":
        return plant.initial_state(scenario.initial_position_enu_m, on_ground=True)
    speeds, tilts = hover_speeds_and_tilts(plant)
    return plant.initial_state(scenario.initial_position_enu_m, on_ground=False,
                               rotor_speed_rad_s=speeds, tilt_rad=tilts)
