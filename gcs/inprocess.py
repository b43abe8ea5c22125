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
from fcu.core import ONBOARD_COLUMNS, FlightCore, onboard_row
from fcu.tracker import VehicleState
from fcu.trajectory import Trajectory, make_trajectory
from gcs.metrics import percentiles_us, tracking_metrics
from sitl.disturbance import Disturbance
from sitl.plant import (
    TRUTH_COLUMNS,
    ActuatorCommand,
    Plant,
    PlantState,
    initial_state,
    rotate_inv,
    truth_row,
)


@dataclass
class RunResult:
    metrics: dict[str, Any]
    truth: np.ndarray  # rows of sitl.plant.TRUTH_COLUMNS
    onboard: np.ndarray  # rows of fcu.core.ONBOARD_COLUMNS

    def truth_col(self, *names: str) -> np.ndarray:
        return self.truth[:, [TRUTH_COLUMNS.index(n) for n in names]]

    def onboard_col(self, *names: str) -> np.ndarray:
        return self.onboard[:, [ONBOARD_COLUMNS.index(n) for n in names]]


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
    state = initial if initial is not None else initial_state(scenario, plant)
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
        seen = state_for_fcu(state)
        ref = trajectory.sample(state.time_us * 1e-6)
        result = core.step(seen, ref)
        step_us = (clock() - t0) * 1e6
        alloc = result.allocation
        p = state.p_enu_m
        truth_rows.append(truth_row(state))
        onboard_rows.append(onboard_row(state.time_us, seen, result, alloc.speed_rad_s,
                                        alloc.tilt_rad, True, step_us))
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
    metrics = build_metrics(scenario, TRUTH_COLUMNS, truth, ONBOARD_COLUMNS, onboard,
                            status=status, wall_time_s=wall, transport="in-process",
                            lockstep=True)
    return RunResult(metrics, truth, onboard)


def build_metrics(scenario: Scenario, truth_columns: tuple[str, ...], truth: np.ndarray,
                  onboard_columns: tuple[str, ...], onboard: np.ndarray, *, status: str,
                  wall_time_s: float, transport: str, lockstep: bool,
                  deadline_misses: int = 0, mission_completed: bool | None = None
                  ) -> dict[str, Any]:
    """metrics.json content (DESIGN.md section 6).

    Joins the plant's truth log with the FCU's onboard log on time_usec; a run diverges at
    the first joined sample whose position error exceeds the scenario's limit or whose state
    is not finite, and its figures cover the run up to that instant (never inf or NaN).
    """
    def cols(columns, rows, *names):
        return rows[:, [columns.index(n) for n in names]]

    t_truth = truth[:, truth_columns.index("time_us")].astype(np.int64)
    t_onb = onboard[:, onboard_columns.index("time_us")].astype(np.int64)
    common_t, i_truth, i_onb = np.intersect1d(t_truth, t_onb, return_indices=True)
    truth, onboard = truth[i_truth], onboard[i_onb]
    p = cols(truth_columns, truth, "px", "py", "pz")
    q = cols(truth_columns, truth, "qw", "qx", "qy", "qz")
    p_d = cols(onboard_columns, onboard, "pdx", "pdy", "pdz")
    q_d = cols(onboard_columns, onboard, "qdw", "qdx", "qdy", "qdz")
    with np.errstate(invalid="ignore", over="ignore"):
        bad = ~np.all(np.isfinite(np.hstack([p, q, p_d, q_d])), axis=1)
        bad |= np.linalg.norm(p - p_d, axis=1) > scenario.divergence_position_m
    end = len(common_t)
    if np.any(bad):
        first = int(np.argmax(bad))
        status = "diverged"
        # Keep the first divergent sample when it is finite: the figures reach that instant.
        end = first + 1 if np.all(np.isfinite(np.hstack([p[first], q[first], p_d[first],
                                                          q_d[first]]))) else first
    sim_time_s = float(common_t[end - 1] * 1e-6) if end else 0.0
    steps = onboard[:end, onboard_columns.index("step_us")]
    sat = onboard[:end, onboard_columns.index("saturated")]
    return {
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
        **tracking_metrics(p[:end], q[:end], p_d[:end], q_d[:end]),
        "fcu_step_us": percentiles_us(steps[np.isfinite(steps)]),
        "deadline_misses": deadline_misses,
        "saturated_steps": int(np.sum(sat > 0)),
        "samples": int(end),
        "mission_completed": (status == "completed") if mission_completed is None
        else mission_completed,
        "status": status,
        "seed": scenario.seed,
    }
