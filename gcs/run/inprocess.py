"""In-process runner: the FCU's pipeline and the simulated world composed in one process
(docs/architecture.md).

`run_scenario` flies a scenario exactly as `gcs run` does through processes, with only
MAVLink and the processes taken away: the FCU built as the FCU process builds it
(`fcu.compose`: the pipeline with the parameters the run sets, the scenario's mission taken
as the mission protocol takes it, armed, the mission started at t = 0), the world the
simulator process steps (`sitl.world`: plant, disturbances, faults, sensors, standing still
before the flight), and the simulator link's float32 rounding applied to the state and to
the actuator commands in the code's frames (`common.wire.rounding`), so both ways give the same
status, events and figures.
"""

from __future__ import annotations

import struct
import time
from collections.abc import Callable

import numpy as np

from common.config.scenario import Scenario, VehicleConfig
from common.logs.columns import ONBOARD_COLUMNS, TRUTH_COLUMNS
from common.outcome import Event
from common.process.startup import compile_time_s
from common.wire.mavlink import encoder, pack, parser
from common.wire.mission_items import PX4_SITL_HOME, MissionItem, item_from_message
from common.wire.mission_messages import item_message
from common.wire.rounding import controls_as_wire, f32_vec3, q_enu_flu_as_wire
from common.wire.simlink import HilSensor, Odometry
from fcu import compose
from fcu.compose import accept_mission, arm_and_start, published_home
from fcu.control.core import onboard_row
from fcu.edge.onboard_log import OnboardLog
from fcu.edge.sim_bridge import pose_from_wire, valid_state
from fcu.estimator.inputs import ImuInput, PoseInput
from fcu.params import ParamError, ParamStore
from fcu.pipeline import Pipeline, StepOutput
from fcu.stages import VehicleState
from gcs.report.metrics import build_metrics
from gcs.run.runio import RunResult
from gcs.run.scenario_mission import scenario_mission, scenario_params
from sitl.plant import ActuatorCommand, PlantState, rotate_inv, truth_row
from sitl.truth_log import TruthLog
from sitl.world import World, obeyed_command


class InProcessError(RuntimeError):
    """A scenario the vehicle refuses (its mission, arming or the start). `result`: the run
    as far as it went, when the vehicle refused it (its metrics with status `aborted` and the
    refusal as `error`, as a run through processes records a refusal), else None."""

    def __init__(self, message: str, result: RunResult | None = None) -> None:
        super().__init__(message)
        self.result = result


def fcu_pipeline(scenario: Scenario) -> tuple[Pipeline, ParamStore]:
    """The pipeline as the FCU process builds it, with the run's parameters in force."""
    try:
        return compose.fcu_pipeline(scenario.vehicle, scenario.gains, scenario.control_rate_hz,
                                    scenario_params(scenario))
    except ParamError as exc:
        raise InProcessError(f"the vehicle refused a parameter: {exc}") from None


def through_wire_item(item: MissionItem) -> MissionItem:
    """A mission item as the FCU receives it in MISSION_ITEM_INT (params and z float32)."""
    mav = encoder(255, 190)
    msg = parser().parse_buffer(pack(mav, item_message(item, 1, 1)))[0]
    return item_from_message(msg)


def state_for_fcu(s: PlantState) -> VehicleState:
    """What the FCU sees: the state as ODOMETRY carries it, each field float32 (rounded in
    ENU/FLU, the same bits; the attitude in the wire's frame), refused as the FCU refuses a
    state no vehicle can be in."""
    state = VehicleState(f32_vec3(s.p_enu_m), q_enu_flu_as_wire(s.q_enu_flu),
                         f32_vec3(rotate_inv(s.q_enu_flu, s.v_enu_m_s)),
                         f32_vec3(s.omega_flu_rad_s))
    if not valid_state(*state):
        raise InProcessError(f"t = {s.time_us * 1e-6:.3f} s: the plant's state is not one "
                             "the FCU accepts")
    return state


def command_for_plant(out: StepOutput, vehicle: VehicleConfig,
                      state: PlantState) -> ActuatorCommand:
    """A step's output as the plant obeys it through HIL_ACTUATOR_CONTROLS: the rotor
    speeds and tilts rounded as the wire rounds them, then `obeyed_command`."""
    speeds, tilts = controls_as_wire(out.speed_rad_s, out.tilt_rad,
                                     vehicle.rotor_speed_max_rad_s)
    return obeyed_command(speeds, tilts, out.armed, state)


_IMU_WIRE = struct.Struct("<6f")  # HIL_SENSOR's accelerometer and gyro fields
_POSE_WIRE = struct.Struct("<9f")  # ODOMETRY's position, attitude and two variances


def imu_for_fcu(h: HilSensor) -> ImuInput:
    """The IMU sample the FCU takes from `h` on the simulator link:
    `fcu.edge.sim_bridge.imu_from_hil_sensor` of `common.wire.simlink.through_wire_hil_sensor`,
    rounding only the fields it reads (a FLU <-> FRD sign flip commutes with the rounding)."""
    a0, a1, a2, g0, g1, g2 = _IMU_WIRE.unpack(_IMU_WIRE.pack(*h.acc_frd_m_s2,
                                                             *h.gyro_frd_rad_s))
    return ImuInput(h.time_usec, (g0, -g1, -g2), (a0, -a1, -a2))


def pose_for_fcu(o: Odometry) -> PoseInput | None:
    """The pose the FCU takes from `o` on the simulator link (None: refused):
    `fcu.edge.sim_bridge.pose_from_odometry` of `common.wire.simlink.through_wire_odometry`,
    rounding only the fields it reads."""
    cov = o.pose_covariance
    v = _POSE_WIRE.unpack(_POSE_WIRE.pack(*o.p_ned_m, *o.q_ned_frd, cov[0], cov[15]))
    return pose_from_wire(o.time_usec, (v[0], v[1], v[2]), (v[3], v[4], v[5], v[6]), v[7],
                          v[8])


def feed_fcu(pipeline: Pipeline, messages: list[HilSensor | Odometry]) -> float:
    """A period's sensor messages as the FCU takes them from the simulator link (float32);
    returns the microseconds the estimator spent on them (part of the FCU's step time)."""
    inputs: list[ImuInput | PoseInput] = []  # as the link's decoder hands them over
    for m in messages:
        if type(m) is HilSensor:
            inputs.append(imu_for_fcu(m))
        else:
            assert isinstance(m, Odometry)
            pose = pose_for_fcu(m)
            if pose is not None:
                inputs.append(pose)
    on_imu, on_pose = pipeline.on_imu, pipeline.on_pose
    t0 = time.perf_counter()
    for x in inputs:
        if isinstance(x, ImuInput):
            on_imu(x)
        else:
            on_pose(x)
    return (time.perf_counter() - t0) * 1e6


def align(pipeline: Pipeline, world: World, dt_s: float,
          record: Callable[[PlantState], None], logged: Callable[[StepOutput], None]) -> None:
    """Before the flight (a sensor feed): the world stands still while time and the sensors
    run, and the FCU answers disarmed, until its estimator is aligned and converged or gives
    up (pipeline.ALIGN_MAX_S; arming is then refused), as with the two processes.
    `record` gets each state sent but the last, `logged` each step's output."""
    assert world.feed is not None
    feed_fcu(pipeline, world.feed.period([world.state]))
    while pipeline.needs_time:
        record(world.state)
        out = pipeline.step(world.state.time_us, dt_s)
        logged(out)
        states = world.advance(command_for_plant(out, world.scenario.vehicle, world.state))
        feed_fcu(pipeline, world.feed.period(states))


class _PackedRows:
    """Rows of float64 values kept packed in one buffer, not as an object per row and per
    value: a 160 s flight's onboard rows take 42 MB rather than about 115 MB of tuples, and the
    flight touches that much less fresh memory (each new page a fault of some microseconds
    on a virtual machine). `array()` gives them back, the same floats to the bit (a Python
    int or bool converted as numpy converts it)."""

    def __init__(self, width: int) -> None:
        self.width = width
        self.data = bytearray()
        self.pack = struct.Struct(f"={width}d").pack

    def add(self, values: tuple[float, ...]) -> None:
        self.data += self.pack(*values)

    def add_array(self, row: np.ndarray) -> None:
        """A row already float64 (`World.row`, a truth row)."""
        self.data += row.tobytes()

    def array(self) -> np.ndarray:
        return np.frombuffer(self.data, dtype=np.float64).reshape(-1, self.width).copy()


# Queued log records are written into the run's buffers every this many control periods,
# as the FCU process writes its log after each step: their objects are freed and reused
# rather than kept until the end.
_LOG_FLUSH_PERIODS = 64


class _RunLogs:
    """truth.ulg and onboard.ulg of an in-process run, as the two processes write them (none
    without `on`); the commander's events logged once each, at the step after they came."""

    def __init__(self, scenario: Scenario, pipeline: Pipeline, values: dict[str, float],
                 on: bool) -> None:
        self.on = on
        self.truth_buf, self.onboard_buf = bytearray(), bytearray()
        self.truth = TruthLog(self.truth_buf, scenario.name) if on else None
        self.onboard = OnboardLog(self.onboard_buf, pipeline, values) if on else None
        self.events_logged = 0

    def record(self, state: PlantState, row: np.ndarray | None = None) -> None:
        if self.truth is not None:
            self.truth.record(state, row)

    def step(self, out: StepOutput, step_us: float, t_us: int, events: list[Event],
             row: tuple[float, ...] | None = None) -> None:
        if self.onboard is not None:
            self.onboard.step(out, step_us, t_us, row)
            if events and len(events) > self.events_logged:
                self.onboard.events(events[self.events_logged:])
                self.events_logged = len(events)

    def flush(self) -> None:
        """What both logs queued, written into their buffers."""
        if self.truth is not None and self.onboard is not None:
            self.truth.flush()
            self.onboard.flush()

    def close(self, events: list[Event]) -> None:
        """The events not logged yet, then both logs closed."""
        if self.truth is not None and self.onboard is not None:
            self.onboard.events(events[self.events_logged:])
            self.truth.close()
            self.onboard.close()

    def files(self) -> tuple[bytes | None, bytes | None]:
        return (bytes(self.truth_buf), bytes(self.onboard_buf)) if self.on else (None, None)


def run_scenario(scenario: Scenario, *, initial: PlantState | None = None,
                 logs: bool = True,
                 before_step: Callable[[int, Pipeline], None] | None = None) -> RunResult:
    """Fly a scenario's mission to its end from `initial` (default: the scenario's start);
    deterministic for a given scenario. With `logs`, the result carries truth.ulg and
    onboard.ulg as the two processes would write them. `before_step(t_us, pipeline)` runs
    before each control step of the flight (what a ground station does, at fixed
    simulated times)."""
    control_dt_us = 1_000_000 // scenario.control_rate_hz
    world = World(scenario, control_dt_us, sensors=scenario.sensors, seed=scenario.seed,
                  initial=initial)
    pipeline, store = fcu_pipeline(scenario)
    run_logs = _RunLogs(scenario, pipeline, store.values, logs)
    truth_rows: list[tuple[float, ...]] = []
    refused = _start(scenario, pipeline, world, control_dt_us * 1e-6, run_logs, truth_rows)
    if refused:
        raise _aborted(scenario, world, pipeline, run_logs, truth_rows, refused)
    world.start_flight()  # the flight's start: the scenario's clock counts from it
    start_us = world.state.time_us
    rows, onboard, wall = _fly(scenario, world, pipeline, run_logs, start_us, before_step)
    cmd = pipeline.commander
    run_logs.close(cmd.events)
    truth = np.vstack([np.array(truth_rows, dtype=float).reshape(-1, len(TRUTH_COLUMNS)),
                       rows])
    events = list(cmd.events)
    metrics = build_metrics(scenario, TRUTH_COLUMNS, truth, ONBOARD_COLUMNS, onboard,
                            events=events, wall_time_s=wall, transport="in-process",
                            lockstep=True, mission_completed=cmd.mission_done,
                            flight_start_us=start_us, compile_time_s=compile_time_s())
    metrics["fcu_params"] = scenario_params(scenario)
    return RunResult(metrics, truth, onboard, events, *run_logs.files())


def _start(scenario: Scenario, pipeline: Pipeline, world: World, dt_s: float,
           run_logs: _RunLogs, truth_rows: list[tuple[float, ...]]) -> str:
    """The scenario's mission uploaded, the estimator aligned on the ground (with a sensor
    profile) or the first state given, the vehicle armed and started: why not, or ''."""
    items = tuple(through_wire_item(item) for item in scenario_mission(scenario))
    refused = accept_mission(pipeline, items, published_home(PX4_SITL_HOME))
    if refused:
        return f"mission refused: {refused}"
    if world.feed is not None:
        def record(s: PlantState) -> None:
            truth_rows.append(truth_row(s))
            run_logs.record(s)

        def logged(out: StepOutput) -> None:
            if run_logs.onboard is not None:
                run_logs.onboard.step(out, 0.0, out.t_us)

        align(pipeline, world, dt_s, record, logged)
    else:
        t_us = world.state.time_us
        pipeline.on_state(t_us, state_for_fcu(world.state), t_us)
    return arm_and_start(pipeline)


def _aborted(scenario: Scenario, world: World, pipeline: Pipeline, run_logs: _RunLogs,
             truth_rows: list[tuple[float, ...]], why: str) -> InProcessError:
    """The refusal, with the run as far as it went: the states so far, nothing flown,
    status aborted (`build_metrics`, as `gcs.run.process_run` records a refused run)."""
    cmd = pipeline.commander
    truth_rows.append(truth_row(world.state))
    run_logs.record(world.state)
    run_logs.close(cmd.events)
    truth = np.array(truth_rows, dtype=float).reshape(-1, len(TRUTH_COLUMNS))
    onboard = np.zeros((0, len(ONBOARD_COLUMNS)))
    metrics = build_metrics(scenario, TRUTH_COLUMNS, truth, ONBOARD_COLUMNS, onboard,
                            events=list(cmd.events), wall_time_s=0.0,
                            transport="in-process", lockstep=True, stopped="aborted",
                            flight_start_us=world.state.time_us,
                            compile_time_s=compile_time_s())
    metrics["error"] = why
    metrics["fcu_params"] = scenario_params(scenario)
    return InProcessError(why, RunResult(metrics, truth, onboard, list(cmd.events),
                                         *run_logs.files()))


def _fly(scenario: Scenario, world: World, pipeline: Pipeline, run_logs: _RunLogs,
         start_us: int, before_step: Callable[[int, Pipeline], None] | None
         ) -> tuple[np.ndarray, np.ndarray, float]:
    """The flight to the scenario's end: (the plant's state rows, the onboard rows, the
    wall time it took)."""
    vehicle, feed, cmd = scenario.vehicle, world.feed, pipeline.commander
    dt_s = (1_000_000 // scenario.control_rate_hz) * 1e-6
    end_us = start_us + round(scenario.duration_s * 1e6)
    clock = time.perf_counter
    input_us = 0.0  # the estimator's work on the period's inputs
    rows, onboard_rows = _PackedRows(len(TRUTH_COLUMNS)), _PackedRows(len(ONBOARD_COLUMNS))
    periods = 0
    wall0 = clock()
    while True:
        state = world.state
        t_us = state.time_us
        row_now = world.row
        rows.add_array(row_now)
        run_logs.record(state, row_now)
        periods += 1
        if periods % _LOG_FLUSH_PERIODS == 0:
            run_logs.flush()
        if feed is None:
            pipeline.on_state(t_us, state_for_fcu(state), t_us)
        if before_step is not None:
            before_step(t_us, pipeline)
        t0 = clock()
        out = pipeline.step(t_us, dt_s)
        step_us = (clock() - t0) * 1e6 + input_us
        row = None
        if out.result is not None and pipeline.state is not None:
            # keyed by the control period answered, as the onboard log keys it (t_us)
            row = onboard_row(pipeline.period_stamp_us, pipeline.state, out.result,
                              out.speed_rad_s, out.tilt_rad, out.armed, step_us)
            onboard_rows.add(row)
        run_logs.step(out, step_us, t_us, cmd.events, row)
        # The step's mission events consumed, as the FCU process's housekeeping consumes
        # them (MISSION_ITEM_REACHED): the log reads only the new ones at its next step.
        cmd.mission_events.clear()
        if t_us >= end_us:
            break
        states = world.advance(command_for_plant(out, vehicle, state))
        if feed is not None:
            input_us = feed_fcu(pipeline, feed.period(states))
    wall = clock() - wall0
    return rows.array(), onboard_rows.array(), wall
