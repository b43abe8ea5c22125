"""In-process runner: the FCU's pipeline and the plant composed in one process (DESIGN.md 1).

`run_scenario` flies a scenario exactly as `gcs run` does through processes, with only
MAVLink and the processes taken away: the same pipeline (commander with the mission executor
fed with the scenario's mission items, tracker, allocator, supervisor, failsafes) with the
parameters the FCU process would have, the same sequence (mission accepted, armed, mission
started at t = 0), and the simulator link's float32 rounding applied to the state and to the
actuator commands, so both ways give the same status, events and figures.

`fly_reference` is the control law alone (tracker and allocator on a given reference), for
tests of the closed-loop error dynamics; it is not a flight.
"""

from __future__ import annotations

import dataclasses
import math
import struct
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from common.config import Scenario, check_sensor_faults
from common.jit import compile_time_s
from common.mavlink import encoder, pack, parser
from common.mission_items import HomePosition, MissionItem, item_from_message, item_message
from common.outcome import Event, diverged
from common.sensors_config import check_servable, resolve_sensor_profile
from common.simlink import (
    HilSensor,
    Odometry,
    through_wire_controls,
    through_wire_hil_sensor,
    through_wire_odometry,
)
from fcu.core import ONBOARD_COLUMNS, FlightCore, onboard_row
from fcu.mission.validation import check_mission, localize
from fcu.onboard_log import OnboardLog
from fcu.params import ParamError, ParamStore, apply_params
from fcu.pipeline import Pipeline, StepOutput
from fcu.sim_bridge import (
    actuator_controls,
    imu_from_hil_sensor,
    pose_from_odometry,
    state_from_odometry,
)
from fcu.telemetry import Home
from fcu.tracker import VehicleState
from fcu.trajectory import Trajectory
from gcs.metrics import build_metrics
from gcs.scenario_mission import scenario_mission
from sitl.actuator_faults import ActuatorFaults
from sitl.disturbance import Disturbance
from sitl.node import command_from_controls, odometry
from sitl.plant import (
    TRUTH_COLUMNS,
    ActuatorCommand,
    Plant,
    PlantState,
    command_row,
    initial_state,
    rotate_inv,
    state_of_row,
    state_row,
    truth_row,
)
from sitl.sensor_feed import SensorFeed
from sitl.truth_log import TruthLog


class InProcessError(RuntimeError):
    """A scenario the vehicle refuses (its mission, arming or the start)."""


@dataclass
class RunResult:
    metrics: dict[str, Any]
    truth: np.ndarray  # rows of sitl.plant.TRUTH_COLUMNS
    onboard: np.ndarray  # rows of fcu.core.ONBOARD_COLUMNS
    events: list[Event] = dataclasses.field(default_factory=list)
    truth_ulog: bytes | None = None  # truth.ulg as the simulator writes it
    onboard_ulog: bytes | None = None  # onboard.ulg as the FCU writes it

    def truth_col(self, *names: str) -> np.ndarray:
        return self.truth[:, [TRUTH_COLUMNS.index(n) for n in names]]

    def onboard_col(self, *names: str) -> np.ndarray:
        return self.onboard[:, [ONBOARD_COLUMNS.index(n) for n in names]]


def apply_overrides(scenario: Scenario, *, controller: str | None = None,
                    ideal_actuators: bool | None = None,
                    duration_s: float | None = None, sensors: str | None = None,
                    seed: int | None = None) -> Scenario:
    """The scenario with the command line's choices (a sensor profile by name or file)."""
    changes: dict[str, Any] = {}
    if sensors is not None:
        changes["sensors"] = resolve_sensor_profile(sensors)
    if seed is not None:
        changes["seed"] = seed
    if controller is not None:
        changes["controller"] = controller
    if ideal_actuators is not None:
        changes["ideal_actuators"] = ideal_actuators
    if duration_s is not None:
        changes["duration_s"] = min(duration_s, scenario.duration_s)
    out = dataclasses.replace(scenario, **changes)
    check_sensor_faults(out.sensor_faults, out.sensors, "--sensors")
    if out.sensors is not None:  # refused before any run, processes or in-process
        check_servable(out.sensors, 1_000_000 // out.physics_rate_hz,
                       1_000_000 // out.control_rate_hz)
    return out


def scenario_params(scenario: Scenario) -> dict[str, float]:
    """Parameters a run sets on the FCU beyond its defaults (the same through processes):
    no lead for actuators without lag; with a sensor profile the estimator's noise figures
    those of the profile's IMU and motion capture and its fusion horizon at the pose's
    latency (as a user tunes EKF2_GYR_NOISE, EKF2_ACC_NOISE, EKF2_EVP_NOISE, EKF2_EVA_NOISE
    and EKF2_EV_DELAY to the vehicle); the scenario's own [params]; last, with a sensor
    profile, the estimator on. Set in this order."""
    params = {"COM_DIV_POS": scenario.divergence_position_m}
    if scenario.ideal_actuators:
        params["CA_LAG_COMP"] = 0.0  # actuators without lag: nothing to lead
    if scenario.uses_sensors:
        assert scenario.sensors is not None
        imu = scenario.sensors.imu
        params["EKF_GYR_NOISE"] = max(imu.gyro_sigma_rad_s, 1e-4)  # the IMU's, per sample
        params["EKF_ACC_NOISE"] = max(imu.accel_sigma_m_s2, 1e-3)
        mocap = scenario.sensors.mocap
        params["EKF_EVP_NOISE"] = max(mocap.position_noise_m, 1e-5)  # trust its covariance
        params["EKF_EVA_NOISE"] = max(mocap.attitude_noise_rad, 1e-5)
        params["EKF_EV_DELAY"] = mocap.latency_s
    params.update(scenario.params)
    if scenario.uses_sensors:
        # Last: the estimator starts (and in lockstep simulated time runs, aligning it) once
        # it is on, so the flight starts at the same instant however the sets were timed.
        params.pop("EKF_EN", None)
        params["EKF_EN"] = 1.0
    return params


def fcu_pipeline(scenario: Scenario) -> tuple[Pipeline, ParamStore]:
    """The pipeline as the FCU process builds it, with the run's parameters in force."""
    pipeline = Pipeline(scenario.vehicle, scenario.gains, scenario.control_rate_hz)
    store = ParamStore(scenario.gains)
    for name, value in scenario_params(scenario).items():
        try:
            store.set(name, value)
        except ParamError as exc:
            raise InProcessError(f"the vehicle refused a parameter: {exc}") from None
    apply_params(store, pipeline)
    return pipeline, store


def fcu_home() -> HomePosition:
    """The home the FCU process converts global-frame items through (its default --home,
    as HOME_POSITION publishes it)."""
    home = Home()
    return HomePosition.published(home.lat_deg, home.lon_deg, home.alt_m)


def through_wire_item(item: MissionItem) -> MissionItem:
    """A mission item as the FCU receives it in MISSION_ITEM_INT (params and z float32)."""
    mav = encoder(255, 190)
    msg = parser().parse_buffer(pack(mav, item_message(item, 1, 1)))[0]
    return item_from_message(msg)


_ODOMETRY_FLOATS = struct.Struct("<13f")  # ODOMETRY's x .. yawspeed fields, as on the wire


def state_for_fcu(s: PlantState) -> VehicleState:
    """What the FCU sees: the state as ODOMETRY carries it, float32 and all (the fields the
    state is read from, rounded as through_wire_odometry rounds them)."""
    odo = odometry(s)
    v = _ODOMETRY_FLOATS.unpack(_ODOMETRY_FLOATS.pack(*odo.p_ned_m, *odo.q_ned_frd,
                                                      *odo.v_frd_m_s, *odo.omega_frd_rad_s))
    state = state_from_odometry(odo._replace(p_ned_m=v[0:3], q_ned_frd=v[3:7],
                                             v_frd_m_s=v[7:10], omega_frd_rad_s=v[10:13]))
    if state is None:
        raise InProcessError(f"t = {s.time_us * 1e-6:.3f} s: the plant's state is not one "
                             "the FCU accepts")
    return state


def feed_fcu(pipeline: Pipeline, messages: list[HilSensor | Odometry]) -> float:
    """A period's sensor messages as the FCU takes them from the simulator link (float32);
    returns the microseconds the estimator spent on them (part of the FCU's step time)."""
    spent = 0.0
    clock = time.perf_counter
    for m in messages:
        if isinstance(m, HilSensor):
            imu = imu_from_hil_sensor(through_wire_hil_sensor(m))
            t0 = clock()
            pipeline.on_imu(imu)
        else:
            pose = pose_from_odometry(through_wire_odometry(m))
            if pose is None:
                continue
            t0 = clock()
            pipeline.on_pose(pose)
        spent += (clock() - t0) * 1e6
    return spent


def align(pipeline: Pipeline, plant: Plant, feed: SensorFeed, state: PlantState,
          substeps: int, dt_s: float, record: Callable[[PlantState], None],
          logged: Callable[[StepOutput], None]) -> PlantState:
    """Before the flight: the world stands still while time and the sensors run, and the
    FCU answers disarmed, until its estimator is aligned and converged or gives up
    (pipeline.ALIGN_MAX_S; arming is then refused), as sitl/node.py.
    `record` gets each state sent but the last, `logged` each step's output."""
    feed_fcu(pipeline, feed.period([state]))
    while pipeline.needs_time:
        record(state)
        logged(pipeline.step(state.time_us, dt_s))
        states = []
        for _ in range(substeps):
            state = state._replace(time_us=state.time_us + plant.dt_us)
            states.append(state)
        feed_fcu(pipeline, feed.period(states))
    return state


def run_scenario(scenario: Scenario, *, initial: PlantState | None = None,
                 logs: bool = True) -> RunResult:
    """Fly a scenario's mission to its end; deterministic for a given scenario. With `logs`,
    the result carries truth.ulg and onboard.ulg as the two processes would write them."""
    vehicle = scenario.vehicle
    physics_dt_us = 1_000_000 // scenario.physics_rate_hz
    control_dt_us = 1_000_000 // scenario.control_rate_hz
    substeps = control_dt_us // physics_dt_us
    plant = Plant(vehicle, dt_us=physics_dt_us, ideal_actuators=scenario.ideal_actuators,
                  ground_enabled=scenario.ground_enabled,
                  disturbance=Disturbance(scenario.force_terms, scenario.torque_terms))
    state = initial if initial is not None else initial_state(scenario, plant)
    pipeline, store = fcu_pipeline(scenario)
    cmd = pipeline.commander
    truth_buf, onboard_buf = bytearray(), bytearray()
    truth_log = TruthLog(truth_buf, scenario.name) if logs else None
    onboard_log = OnboardLog(onboard_buf, pipeline, store.values) if logs else None
    items = tuple(through_wire_item(item) for item in scenario_mission(scenario))
    home = fcu_home()
    check = check_mission(items, cmd.limits, home)
    if check.result != 0:
        raise InProcessError(f"mission refused: MAV_MISSION_RESULT {check.result}: "
                             f"{check.reason}")
    cmd.set_mission(localize(items, home))
    dt_s = control_dt_us * 1e-6
    truth_rows: list[tuple[float, ...]] = []
    onboard_rows: list[tuple[float, ...]] = []
    feed = None
    if scenario.uses_sensors:
        assert scenario.sensors is not None
        feed = SensorFeed(scenario.sensors, scenario.seed, plant, control_dt_us)

        def record(s: PlantState) -> None:
            truth_rows.append(truth_row(s))
            if truth_log is not None:
                truth_log.record(s)

        def logged(out: StepOutput) -> None:
            if onboard_log is not None:
                onboard_log.step(out, 0.0, out.t_us)

        state = align(pipeline, plant, feed, state, substeps, dt_s, record, logged)
    else:
        pipeline.on_state(state.time_us, state_for_fcu(state), state.time_us)
    for what, (code, text) in (("arming", pipeline.arm()),
                               ("mission start", cmd.mission_start(0))):
        if code != 0:
            raise InProcessError(f"{what} refused: {text}")
    start_us = state.time_us  # the flight's start: the scenario's clock counts from it
    plant.disturbance = plant.disturbance.from_time(start_us * 1e-6)
    if feed is not None:
        feed.start_flight(start_us, scenario.sensor_faults)
    faults = ActuatorFaults(scenario.actuator_faults, start_us)
    end_us = start_us + round(scenario.duration_s * 1e6)
    clock = time.perf_counter
    logged_events = 0
    input_us = 0.0  # the estimator's work on the period's inputs
    row = state_row(state)  # the plant's state as its kernels keep it (a truth row)
    substates = np.empty((substeps, len(TRUTH_COLUMNS)))
    rows: list[np.ndarray] = []
    wall0 = clock()
    while True:
        t_us = state.time_us
        rows.append(row)
        if truth_log is not None:
            truth_log.record(state)
        if feed is None:
            pipeline.on_state(t_us, state_for_fcu(state), t_us)
        t0 = clock()
        out = pipeline.step(t_us, dt_s)
        step_us = (clock() - t0) * 1e6 + input_us
        if out.result is not None and pipeline.state is not None:
            onboard_rows.append(onboard_row(t_us, pipeline.state, out.result, out.speed_rad_s,
                                            out.tilt_rad, out.armed, step_us))
        if onboard_log is not None:
            onboard_log.step(out, step_us, t_us)
            if cmd.events and len(cmd.events) > logged_events:
                onboard_log.events(cmd.events[logged_events:])
                logged_events = len(cmd.events)
        if t_us >= end_us:
            break
        wire = through_wire_controls(actuator_controls(out, vehicle.rotor_speed_max_rad_s,
                                                       lockstep=True))
        command = command_from_controls(wire.controls, wire.mode, vehicle, state)
        if faults.active:  # a failed actuator is told what it is told at each physics step
            for k in range(substeps):
                applied = faults.apply(command, state_of_row(row.tolist()))
                plant.step_rows(row, command_row(applied), substates[k:k + 1])
                row = substates[k].copy()
        else:
            plant.step_rows(row, command_row(command), substates)
            row = substates[-1].copy()
        if feed is not None:
            states = [state_of_row(r) for r in substates.tolist()]
            state = states[-1]
            input_us = feed_fcu(pipeline, feed.period(states))
        else:
            state = state_of_row(row.tolist())
    wall = clock() - wall0

    if truth_log is not None and onboard_log is not None:
        onboard_log.events(cmd.events[logged_events:])
        truth_log.close()
        onboard_log.close()
    truth = np.vstack([np.array(truth_rows, dtype=float).reshape(-1, len(TRUTH_COLUMNS)),
                       *rows])
    onboard = np.array(onboard_rows, dtype=float).reshape(-1, len(ONBOARD_COLUMNS))
    events = list(cmd.events)
    metrics = build_metrics(scenario, TRUTH_COLUMNS, truth, ONBOARD_COLUMNS, onboard,
                            events=events, wall_time_s=wall, transport="in-process",
                            lockstep=True, mission_completed=cmd.mission_done,
                            flight_start_us=start_us, compile_time_s=compile_time_s())
    metrics["fcu_params"] = scenario_params(scenario)
    return RunResult(metrics, truth, onboard, events,
                     bytes(truth_buf) if logs else None, bytes(onboard_buf) if logs else None)


def fly_reference(scenario: Scenario, trajectory: Trajectory,
                  initial: PlantState | None = None) -> RunResult:
    """The control law alone on `trajectory`: tracker and allocator over the plant, every
    control period, until the scenario's end or divergence (tests of eqs. 18-21)."""
    vehicle = scenario.vehicle
    physics_dt_us = 1_000_000 // scenario.physics_rate_hz
    control_dt_us = 1_000_000 // scenario.control_rate_hz
    plant = Plant(vehicle, dt_us=physics_dt_us, ideal_actuators=scenario.ideal_actuators,
                  ground_enabled=scenario.ground_enabled,
                  disturbance=Disturbance(scenario.force_terms, scenario.torque_terms))
    state = initial if initial is not None else initial_state(scenario, plant)
    core = FlightCore(vehicle, scenario.gains, scenario.control_rate_hz, state.tilt_rad)
    end_us = round(scenario.duration_s * 1e6)
    truth_rows: list[tuple[float, ...]] = []
    onboard_rows: list[tuple[float, ...]] = []
    wall0 = time.perf_counter()
    while state.time_us <= end_us:
        seen = VehicleState(state.p_enu_m, state.q_enu_flu,
                            rotate_inv(state.q_enu_flu, state.v_enu_m_s), state.omega_flu_rad_s)
        ref = trajectory.sample(state.time_us * 1e-6)
        result = core.step(seen, ref)
        alloc = result.allocation
        truth_rows.append(truth_row(state))
        onboard_rows.append(onboard_row(state.time_us, seen, result, alloc.speed_rad_s,
                                        alloc.tilt_rad, True, 0.0))
        finite = all(math.isfinite(c) for c in (*alloc.speed_rad_s, *alloc.tilt_rad))
        if diverged(math.dist(state.p_enu_m, ref.p_enu_m), finite,
                    scenario.divergence_position_m) or state.time_us >= end_us:
            break
        command = ActuatorCommand(alloc.speed_rad_s, alloc.tilt_rad)
        for _ in range(control_dt_us // physics_dt_us):
            state = plant.step(state, command)
    truth = np.array(truth_rows, dtype=float)
    onboard = np.array(onboard_rows, dtype=float)
    metrics = build_metrics(scenario, TRUTH_COLUMNS, truth, ONBOARD_COLUMNS, onboard,
                            events=[], wall_time_s=time.perf_counter() - wall0,
                            transport="in-process", lockstep=True, mission_completed=False)
    return RunResult(metrics, truth, onboard, [])
