"""The simulated world of one run: the plant with its disturbances, the actuator faults and
the sensors, from the first state to the flight's end (docs/model.md#plant, docs/simulator-link.md).

The simulator process (`sitl.server`) and the in-process runner (`gcs.run.inprocess`) step the
same `World`, so both fly the same physics with the same faults and sensor samples.

Before the flight starts (the first armed answer, `start_flight`) the world stands still
while time runs, one control period at a time: the sensors sample a vehicle at rest, so the
FCU's estimator aligns on the ground. From the flight's start the scenario's clock counts:
its disturbances, actuator faults and sensor faults.
"""

from __future__ import annotations

import math

import numpy as np

from common.config.scenario import Scenario, VehicleConfig
from common.config.sensors import SensorProfile
from common.logs.columns import TRUTH_COLUMNS
from common.wire.mav_enums import MAV_MODE_FLAG
from sitl.actuator_faults import ActuatorFaults
from sitl.plant import (
    ActuatorCommand,
    ContactImpulses,
    Plant,
    PlantState,
    command_row,
    initial_state,
    scenario_plant,
    state_of_row,
    state_row,
)
from sitl.sensor_feed import SensorFeed

_LANDED = TRUTH_COLUMNS.index("landed")


def obeyed_command(speeds_rad_s: tuple[float, ...], tilts_rad: tuple[float, ...], armed: bool,
                   state: PlantState) -> ActuatorCommand:
    """What the actuators do with a command: rotor speeds zero unless armed, a speed that
    is not finite zero, a tilt that is not finite the current tilt."""
    isfinite = math.isfinite
    if armed:  # a finite sum: all finite; else (NaN, inf, overflow) each one
        speeds = tuple(speeds_rad_s) if isfinite(sum(speeds_rad_s)) else \
            tuple([w if isfinite(w) else 0.0 for w in speeds_rad_s])
    else:
        speeds = (0.0,) * len(speeds_rad_s)
    tilts = tilts_rad
    if not isfinite(sum(tilts)):
        tilts = tuple([c if isfinite(c) else t for c, t in zip(tilts, state.tilt_rad, strict=True)])
    return ActuatorCommand(speeds, tuple(tilts))


def command_from_controls(controls: tuple[float, ...], mode: int, vehicle: VehicleConfig,
                          state: PlantState) -> ActuatorCommand:
    """HIL_ACTUATOR_CONTROLS as the plant obeys it: controls[0..n) x w_max rotor speeds
    (zero unless SAFETY_ARMED), controls[n..2n) tilts (`obeyed_command`)."""
    n = vehicle.n_rotors
    w_max = vehicle.rotor_speed_max_rad_s
    return obeyed_command(tuple([c * w_max for c in controls[:n]]), controls[n:2 * n],
                          bool(mode & MAV_MODE_FLAG.MAV_MODE_FLAG_SAFETY_ARMED), state)


def start_flight(scenario: Scenario, plant: Plant, faults: ActuatorFaults,
                 feed: SensorFeed | None, t_us: int) -> None:
    """The flight starts at t_us: the scenario's disturbances, actuator faults and sensor
    faults count from it."""
    plant.disturbance = plant.disturbance.from_time(t_us * 1e-6)
    faults.start_flight(t_us)
    if feed is not None:
        feed.start_flight(t_us, scenario.sensor_faults)


class World:
    """The scenario's plant, actuator faults and sensors (a model sensor profile: `feed`;
    None: the exact state goes out), stepped one control period of `control_dt_us` at a
    time from `initial` (default: the scenario's start)."""

    def __init__(self, scenario: Scenario, control_dt_us: int, *,
                 sensors: SensorProfile | None = None, seed: int = 0, home_alt_m: float = 0.0,
                 initial: PlantState | None = None) -> None:
        self.scenario = scenario
        self.plant = scenario_plant(scenario, 1_000_000 // scenario.physics_rate_hz)
        self.control_dt_us = control_dt_us
        self.substeps = control_dt_us // self.plant.dt_us
        self.state = initial if initial is not None else initial_state(scenario, self.plant)
        self.faults = ActuatorFaults(scenario.actuator_faults)
        self.feed = SensorFeed(sensors, seed, self.plant, control_dt_us, home_alt_m) \
            if sensors is not None and not sensors.is_truth else None
        self.flight_start_us: int | None = None  # the first armed answer's state stamp
        self._row: np.ndarray | None = None  # the state as the kernels keep it, in flight
        self._substates = np.empty((self.substeps, len(TRUTH_COLUMNS)))
        self._impulses = ContactImpulses()  # ground impulses since `take_contact_dv`

    def _contacts(self, before: np.ndarray, rows: list[list[float]]) -> None:
        """Add the touchdowns' velocity changes (`Plant.contact_dv_enu`) of these steps
        (`rows`: the steps' state rows after `before`)."""
        landed = [r[_LANDED] != 0.0 for r in rows]
        if not any(landed) or (before[_LANDED] != 0.0 and all(landed)):
            return
        for k, row in enumerate(rows):
            a = before.tolist() if k == 0 else rows[k - 1]
            if landed[k] and a[_LANDED] == 0.0:
                self._impulses.add(self.plant.contact_dv_enu(state_of_row(a),
                                                             state_of_row(row)))

    def take_contact_dv(self) -> tuple[float, float, float]:
        """The ground contact's velocity change since the last call (ENU, m/s): what an
        accelerometer sampled now over that interval adds to the specific force (the exact
        state's HIL_SENSOR; a sensor feed keeps its own)."""
        return self._impulses.take()

    @property
    def row(self) -> np.ndarray:
        """The current state as a state row (a truth row; a new array each period)."""
        return self._row if self._row is not None else state_row(self.state)

    def start_flight(self) -> None:
        """The flight starts at the current state (`start_flight`)."""
        self.flight_start_us = self.state.time_us
        start_flight(self.scenario, self.plant, self.faults, self.feed, self.state.time_us)

    def advance(self, command: ActuatorCommand) -> list[PlantState]:
        """One control period under `command` held (the actuator faults applied at each
        physics step; before the flight the world stands still while time runs). Returns
        the states the sensors need, in time order: every physics step's with a sensor
        feed, else the period's last."""
        if self.flight_start_us is None:
            states = []
            s, dt_us = self.state, self.plant.dt_us
            for _ in range(self.substeps):
                s = s._replace(time_us=s.time_us + dt_us)
                states.append(s)
            self.state = s
            return states
        row = self.row
        out = self._substates
        if self.faults.active:  # a failed actuator is told what it is told at each step
            for k in range(self.substeps):
                applied = self.faults.apply(command, state_of_row(row.tolist()))
                self.plant.step_rows(row, command_row(applied), out[k:k + 1])
                row = out[k]
        else:
            self.plant.step_rows(row, command_row(command), out)
        rows = out.tolist()
        self._contacts(row, rows)
        self._row = out[-1].copy()
        if self.feed is not None:
            states = [state_of_row(r) for r in rows]
        else:
            states = [state_of_row(rows[-1])]
        self.state = states[-1]
        return states

    def physics_step(self, command: ActuatorCommand) -> PlantState:
        """One physics step under `command` (real time: the world never stands still)."""
        before = self.state
        self.state = self.plant.step(self.state, self.faults.apply(command, self.state))
        self._row = None
        self._impulses.add(self.plant.contact_dv_enu(before, self.state))
        return self.state
