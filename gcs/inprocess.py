"""In-process runner: the FCU core and the plant composed in one process (DESIGN.md 1).

The controller runs at the control rate over the plant's physics rate with a zero-order hold
on the actuator command; both share one simulated clock in integer microseconds. Returns
the time series and the metrics of DESIGN.md section 6 (`transport: "in-process"`).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from common.config import Scenario
from fcu.allocation import hover_command
from fcu.core import FlightCore
from fcu.tracker import VehicleState
from fcu.trajectory import Trajectory, make_trajectory
from gcs.metrics import percentiles_us, tracking_metrics
from sitl.disturbance import Disturbance
from sitl.plant import ActuatorCommand, Plant, PlantState, rotate_inv

# Column layout of the logs (one row per control step).
TRUTH_COLUMNS = ("time_us", "px", "py", "pz", "vx", "vy", "vz", "qw", "qx", "qy", "qz",
                 "wx", "wy", "wz", *(f"rotor{i}" for i in range(6)),
                 *(f"tilt{i}" for i in range(6)), "landed")
ONBOARD_COLUMNS = ("time_us", "pdx", "pdy", "pdz", "qdw", "qdx", "qdy", "qdz",
                   "fx", "fy", "fz", "tx", "ty", "tz",
                   *(f"rotor_cmd{i}" for i in range(6)), *(f"tilt_cmd{i}" for i in range(6)),
                   *(f"tilt_raw{i}" for i in range(6)), "saturated", "step_us")


@dataclass
class RunResult:
    metrics: dict[str, Any]
    truth: np.ndarray  # rows of TRUTH_COLUMNS
    onboard: np.ndarray  # rows of ONBOARD_COLUMNS


def apply_overrides(scenario: Scenario, *, controller: str | None = None,
                    ideal_actuators: bool | None = None,
                    duration_s: float | None = None) -> Scenario:
    changes: dict[str, Any] = {}
    if controller is not None:
        changes["controller"] = controller
    if ideal_actuators is not None:
        changes["ideal_actuators"] = ideal_actuators
    if duration_s is not None:
        changes["duration_s"] = min(duration_s, scenario.duration_s)
    return dataclasses.replace(scenario, **changes)


def initial_plant_state(scenario: Scenario, plant: Plant) -> PlantState:
    if scenario.start == "ground":
        return plant.initial_state(scenario.initial_position_enu_m, on_ground=True)
    speeds, tilts = hover_command(scenario.vehicle)
    return plant.initial_state(scenario.initial_position_enu_m, on_ground=False,
                               rotor_speed_rad_s=speeds, tilt_rad=tilts)


def state_for_fcu(s: PlantState) -> VehicleState:
    """What the FCU sees: pose and body-frame twist (as ODOMETRY carries them)."""
    return VehicleState(s.p_enu_m, s.q_enu_flu, rotate_inv(s.q_enu_flu, s.v_enu_m_s),
                        s.omega_flu_rad_s)


def run_scenario(scenario: Scenario, *, trajectory: Trajectory | None = None,
                 initial: PlantState | None = None) -> RunResult:
    """Fly a scenario to its end or to divergence; deterministic for a given scenario.

    `trajectory` and `initial` replace the scenario's reference and start state (tests).
    """
    vehicle = scenario.vehicle
    physics_dt_us = 1_000_000 // scenario.physics_rate_hz
    control_dt_us = 1_000_000 // scenario.control_rate_hz
    substeps = control_dt_us // physics_dt_us
    plant = Plant(vehicle, dt_us=physics_dt_us, ideal_actuators=scenario.ideal_actuators,
                  ground_enabled=scenario.ground_enabled,
                  disturbance=Disturbance(scenario.force_terms, scenario.torque_terms))
    state = initial if initial is not None else initial_plant_state(scenario, plant)
    core = FlightCore(vehicle, scenario.gains, scenario.control_rate_hz, state.tilt_rad)
    if trajectory is None:
        trajectory = make_trajectory(scenario.trajectory)
    end_us = round(scenario.duration_s * 1e6)
    limit = scenario.divergence_position_m

    truth_rows: list[tuple[float, ...]] = []
    onboard_rows: list[tuple[float, ...]] = []
    status = "completed"
    wall0 = time.perf_counter()
    clock = time.perf_counter
    while state.time_us <= end_us:
        t0 = clock()
        ref = trajectory.sample(state.time_us * 1e-6)
        result = core.step(state_for_fcu(state), ref)
        step_us = (clock() - t0) * 1e6
        alloc, out = result.allocation, result.tracker
        p = state.p_enu_m
        truth_rows.append((state.time_us, *p, *state.v_enu_m_s, *state.q_enu_flu,
                           *state.omega_flu_rad_s, *state.rotor_speed_rad_s, *state.tilt_rad,
                           float(state.landed)))
        onboard_rows.append((state.time_us, *ref.p_enu_m, *ref.q_enu_flu, *out.force_flu_n,
                             *out.torque_flu_nm, *alloc.speed_rad_s, *alloc.tilt_rad,
                             *alloc.tilt_raw_rad, float(alloc.saturated), step_us))
        pd = ref.p_enu_m
        err = math.sqrt((p[0] - pd[0]) ** 2 + (p[1] - pd[1]) ** 2 + (p[2] - pd[2]) ** 2)
        if not math.isfinite(err) or err > limit or not all(
                math.isfinite(c) for c in (*alloc.speed_rad_s, *alloc.tilt_rad)):
            status = "diverged"
            break
        if state.time_us >= end_us:
            break
        cmd = ActuatorCommand(alloc.speed_rad_s, alloc.tilt_rad)
        for _ in range(substeps):
            state = plant.step(state, cmd)
    wall = time.perf_counter() - wall0

    truth = np.array(truth_rows, dtype=float)
    onboard = np.array(onboard_rows, dtype=float)
    metrics = build_metrics(scenario, truth, onboard, status=status, wall_time_s=wall,
                            transport="in-process", lockstep=True)
    return RunResult(metrics, truth, onboard)


def build_metrics(scenario: Scenario, truth: np.ndarray, onboard: np.ndarray, *, status: str,
                  wall_time_s: float, transport: str, lockstep: bool,
                  deadline_misses: int = 0, mission_completed: bool | None = None
                  ) -> dict[str, Any]:
    """metrics.json content; figures cover the finite rows only (never inf or NaN)."""
    p, q = truth[:, 1:4], truth[:, 7:11]
    p_d, q_d = onboard[:, 1:4], onboard[:, 4:8]
    finite = np.all(np.isfinite(np.hstack([p, q, p_d, q_d])), axis=1)
    if not np.all(finite):
        cut = int(np.argmin(finite))
        p, q, p_d, q_d = p[:cut], q[:cut], p_d[:cut], q_d[:cut]
        status = "diverged"
    sim_time_s = float(truth[-1, 0] * 1e-6) if len(truth) else 0.0
    steps = onboard[:, -1]
    metrics: dict[str, Any] = {
        "scenario": scenario.name,
        "controller": scenario.controller,
        "lockstep": lockstep,
        "transport": transport,
        "sim_time_s": sim_time_s,
        "wall_time_s": wall_time_s,
        "real_time_factor": sim_time_s / wall_time_s if wall_time_s > 0 else 0.0,
        "control_rate_hz": scenario.control_rate_hz,
        "physics_rate_hz": scenario.physics_rate_hz,
        "ideal_actuators": scenario.ideal_actuators,
        "damping": scenario.gains.damping,
        **tracking_metrics(p, q, p_d, q_d),
        "fcu_step_us": percentiles_us(steps[np.isfinite(steps)]),
        "deadline_misses": deadline_misses,
        "saturated_steps": int(np.sum(onboard[:, ONBOARD_COLUMNS.index("saturated")] > 0)),
        "mission_completed": (status == "completed") if mission_completed is None
        else mission_completed,
        "status": status,
        "seed": scenario.seed,
    }
    return metrics
