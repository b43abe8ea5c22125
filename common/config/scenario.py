"""Typed configuration loaded from TOML: vehicle, gains and scenarios.

Every loader validates types, ranges, unknown and missing keys, and raises `ConfigError`
naming the file, the key and what was expected (`common.config.reader`). Gains are checked
against the Routh-Hurwitz condition of the paper's eq. (20)-(23): k_p, k_d > 0, k_i >= 0,
k_p k_d > k_i.

This module is the configuration's interface: it loads scenarios and re-exports (`__all__`)
what they are made of, from the modules that read each part: the vehicle
(`common.config.vehicle`), the gains (`common.config.gains`), the disturbance terms and
faults (`common.config.scenario_terms`) and the sensor profiles (`common.config.sensors`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from common.config.gains import Gains, check_stability, load_gains, parse_gains
from common.config.keys import Key, KeyTable
from common.config.reader import ConfigError, Table, read_toml
from common.config.scenario_terms import (
    ACTUATOR_FAULT_KINDS,
    SENSOR_FAULT_KINDS,
    ActuatorFault,
    DisturbanceTerm,
    SensorFault,
    check_sensor_faults,
    parse_actuator_faults,
    parse_sensor_faults,
    parse_terms,
)
from common.config.sensors import SensorProfile, check_servable, resolve_sensor_profile
from common.config.vehicle import VehicleConfig, load_vehicle, parse_vehicle
from common.outcome import DIVERGENCE_ATTITUDE_HOLD_S, DIVERGENCE_ATTITUDE_RAD
from common.vehicle_constants import N_ROTORS

__all__ = [
    "ACTUATOR_FAULT_KINDS", "CONTROLLERS", "INLINE", "N_ROTORS", "SENSOR_FAULT_KINDS",
    "STARTS", "TRAJECTORIES", "ActuatorFault", "ConfigError", "DisturbanceTerm", "Gains",
    "Scenario", "SensorFault", "TrajectoryConfig", "VehicleConfig", "check_sensor_faults",
    "check_stability", "load_gains", "load_scenario", "load_vehicle", "parse_gains",
    "parse_vehicle", "resolved_scenario_data", "scenario_from_data",
]

Vec3 = tuple[float, float, float]

# ----------------------------------------------------------------------------------------
# Scenarios (docs/model.md#scenarios)
# ----------------------------------------------------------------------------------------

CONTROLLERS = ("pid", "pd")
TRAJECTORIES = ("case1_figure8", "hover", "mission")
STARTS = ("ground", "hover")


SCENARIO_KEYS = KeyTable("", (
    Key("name", "string", "the run's name"),
    Key("duration_s", "number", "simulated seconds", "s", lo=0.0, lo_open=True),
    Key("controller", "string", "`pid` (eq. 16) or `pd` (eq. 33)", default="pid",
        choices=CONTROLLERS),
    Key("vehicle", "raw", "a vehicle file (relative to the scenario), or an inline table of "
        "its keys", type_doc="file name or table"),
    Key("seed", "integer", "the sensors' and disturbances' random seed", default=0, lo=0),
    Key("ground", "boolean", "whether the ground exists (Case II switches it off)",
        default_doc="true when `initial.start` is `ground`"),
    Key("sensors", "string", "a sensor profile: a name of `config/sensors/` (`mocap-indoor`) "
        "or a file; the FCU then flies on its estimator", default="truth",
        default_doc="the exact state, no estimator"),
    Key("divergence_position_m", "number", "the position error that ends a run as diverged "
        "(set on the FCU as COM_DIV_POS)", "m", 10.0, lo=0.1, hi=1000.0),
    Key("divergence_attitude_rad", "number", "the attitude error that, held "
        "`divergence_attitude_hold_s`, ends a run as diverged", "rad",
        DIVERGENCE_ATTITUDE_RAD, lo=0.1, hi=math.pi),
    Key("divergence_attitude_hold_s", "number", "how long the attitude error must hold", "s",
        DIVERGENCE_ATTITUDE_HOLD_S, lo=0.0, hi=60.0),
    Key("gains", "table", "the tracker's gains (`[gains]`)"),
    Key("rates", "table", "the loops' rates (`[rates]`)", default={}),
    Key("initial", "table", "where the vehicle starts (`[initial]`)"),
    Key("trajectory", "table", "what the vehicle flies (`[trajectory]`)"),
    Key("disturbance", "table", "body-frame disturbance terms (`[[disturbance.force]]`, "
        "`[[disturbance.torque]]`)", default={}),
    Key("actuators", "table", "the actuators' model (`[actuators]`)", default={}),
    Key("params", "table", "FCU parameters the run sets (`[params]`)", default={}),
    Key("sensor_fault", "tables", "faults injected into the simulated sensors",
        default_doc="none"),
    Key("actuator_fault", "tables", "rotors and tilt servos failing during the flight",
        default_doc="none"),
))

GAINS_TABLE_KEYS = KeyTable("gains", (
    Key("pid", "raw", "the PID gains (eq. 30): a gain file or an inline table",
        type_doc="file name or table"),
    Key("pd", "raw", "the PD baseline's gains (eq. 33): a file or a table with "
        "`ki_r = ki_d = 0`", type_doc="file name or table"),
))

RATES_KEYS = KeyTable("rates", (
    Key("control_hz", "integer", "the control loop's rate", "Hz", 500, lo=1, hi=1000),
    Key("physics_hz", "integer", "the plant's physics rate", "Hz", 1000, lo=1, hi=100000,
        range_doc="a multiple of `control_hz`"),
))

INITIAL_KEYS = KeyTable("initial", (
    Key("start", "string", "`ground`: resting at the position, rotors stopped; `hover`: "
        "airborne at hover speed", choices=STARTS),
    Key("position_enu_m", "vec3", "the start position (ENU)", "m", (0.0, 0.0, 0.0)),
))

TRAJECTORY_KEYS = KeyTable("trajectory", (
    Key("kind", "string", "`case1_figure8`: Case I, the quintic rise, a hover, the "
        "figure-infinity; `hover`: a hover; `mission`: a mission file, uploaded as `gcs "
        "mission upload` would send it", choices=TRAJECTORIES),
    Key("position_enu_m", "vec3", "`hover`, `case1_figure8`: the hover's or the figure's "
        "centre (ENU)", "m", default_doc="the initial position"),
    Key("mission", "string", "`mission` only: a mission file (TOML, `.plan` or WPL), "
        "relative to the scenario", type_doc="file name", default_doc="required for `mission`"),
    Key("rise_height_m", "number", "`case1_figure8`: the rise's height", "m", 5.0),
    Key("rise_end_s", "number", "`case1_figure8`: when the rise ends", "s", 10.0, lo=0.0,
        lo_open=True),
    Key("figure_start_s", "number", "`case1_figure8`: when the figure starts", "s", 20.0,
        lo=0.0, range_doc=">= rise_end_s"),
    Key("figure_end_s", "number", "`case1_figure8`: when the figure ends", "s", 140.0,
        lo=0.0, range_doc="> figure_start_s"),
    Key("amplitude_m", "number", "`case1_figure8`: the figure's amplitude", "m", 5.0, lo=0.0),
    Key("axis_enu", "vec3", "`case1_figure8`: the axis the attitude turns about",
        default=(1.0, 2.0, 3.0)),
))

DISTURBANCE_KEYS = KeyTable("disturbance", (
    Key("force", "tables", "force terms (N), summed", default_doc="none"),
    Key("torque", "tables", "torque terms (N m), summed", default_doc="none"),
))

ACTUATORS_KEYS = KeyTable("actuators", (
    Key("ideal", "boolean", "actuators that follow their commands at once (the speed limit "
        "stays)", default=False),
))

PARAMS_KEYS = KeyTable("params", (
    Key("*", "number", "any FCU parameter (a name of at most 16 characters, "
        "[parameters](parameters.md)) and its value, set by PARAM_SET before the mission; a "
        "refused one ends the run with the vehicle's reason", default_doc="none",
        range_doc="the parameter's"),
))


@dataclass(frozen=True)
class TrajectoryConfig:
    kind: str
    position_enu_m: Vec3 = (0.0, 0.0, 0.0)
    rise_height_m: float = 5.0
    rise_end_s: float = 10.0
    figure_start_s: float = 20.0
    figure_end_s: float = 140.0
    amplitude_m: float = 5.0
    axis_enu: Vec3 = (1.0, 2.0, 3.0)
    mission_file: str = ""  # kind "mission": a mission file (TOML or QGC WPL), resolved


@dataclass(frozen=True)
class Scenario:
    """Everything one run needs; file paths already resolved and loaded."""

    name: str
    duration_s: float
    controller: str
    vehicle: VehicleConfig
    gains_pid: Gains
    gains_pd: Gains
    control_rate_hz: int
    physics_rate_hz: int
    ideal_actuators: bool
    ground_enabled: bool
    start: str
    initial_position_enu_m: Vec3
    trajectory: TrajectoryConfig
    force_terms: tuple[DisturbanceTerm, ...] = ()
    torque_terms: tuple[DisturbanceTerm, ...] = ()
    seed: int = 0
    divergence_position_m: float = 10.0
    # the run status's attitude rule (common.outcome.diverged_rows): an attitude error above
    # divergence_attitude_rad held for divergence_attitude_hold_s without a break
    divergence_attitude_rad: float = DIVERGENCE_ATTITUDE_RAD
    divergence_attitude_hold_s: float = DIVERGENCE_ATTITUDE_HOLD_S
    source: str = ""
    files: dict[str, str] = field(default_factory=dict)
    # The simulated sensors (config/sensors/): None or a kind "truth" profile means the
    # exact state on the wire and no estimator (docs/simulator-link.md).
    sensors: SensorProfile | None = None
    # FCU parameters the run sets (PARAM_SET before the mission; the table [params]), e.g.
    # CA_LAG_COMP = 0 for the paper's plain allocation; names and ranges are the FCU's.
    params: dict[str, float] = field(default_factory=dict)
    # Faults injected into the simulated sensors ([[sensor_fault]]; a sensor profile needed).
    sensor_faults: tuple[SensorFault, ...] = ()
    # Rotors and tilt servos failing during the flight ([[actuator_fault]]).
    actuator_faults: tuple[ActuatorFault, ...] = ()

    @property
    def uses_sensors(self) -> bool:
        """Whether the FCU flies on its estimator (a sensor model, not the exact state)."""
        return self.sensors is not None and not self.sensors.is_truth

    @property
    def gains(self) -> Gains:
        return self.gains_pid if self.controller == "pid" else self.gains_pd


INLINE = "<inline>"  # Scenario.files entry of a vehicle or gain table given in the scenario


def load_scenario(path: str | Path, *, firmware: bool = False) -> Scenario:
    """Load a scenario and the vehicle and gain files it names (paths relative to it).
    `firmware`: served to ArduPilot or PX4 (`sitl --protocol ardupilot-json|px4-hil`), whose
    own sensor rates the plant checks when it serves them; otherwise its sensor profile must
    be servable to this project's FCU (`check_servable`: 500 Hz IMU and more, a sample at
    the end of every control period)."""
    path = Path(path)
    return scenario_from_data(read_toml(path), path, firmware=firmware)


def resolved_scenario_data(path: str | Path) -> dict[str, Any]:
    """The scenario file as data with its vehicle and gain files inlined as tables and its
    other file references made absolute: one self-contained description of a run, which
    `scenario_from_data` loads exactly as `load_scenario` loads the file (campaigns set
    keys in it and hash it)."""
    path = Path(path)
    data = read_toml(path)
    base = path.parent
    t = Table(data, str(path))

    def inline(value: Any, key: str) -> Any:
        if isinstance(value, str):
            return read_toml((base / value).resolve())
        if isinstance(value, dict):
            return value
        raise t.error(key, "a file name or a table")

    data["vehicle"] = inline(data.get("vehicle"), "vehicle")
    gains = data.get("gains")
    if not isinstance(gains, dict):
        raise t.error("gains", "a table")
    data["gains"] = {k: inline(v, f"gains.{k}") for k, v in gains.items()}
    traj = data.get("trajectory")
    if isinstance(traj, dict) and isinstance(traj.get("mission"), str):
        traj["mission"] = str((base / traj["mission"]).resolve())
    sensors = data.get("sensors")
    if isinstance(sensors, str) and (base / sensors).is_file():
        data["sensors"] = str((base / sensors).resolve())
    return data


def _rates(t: Table, source: str) -> tuple[int, int]:
    """`[rates]`: the control and physics rates (Hz), physics a multiple of control."""
    rates = SCENARIO_KEYS["rates"].read(t)
    control_hz = RATES_KEYS["control_hz"].read(rates)
    physics_hz = RATES_KEYS["physics_hz"].read(rates)
    rates.finish()
    if physics_hz % control_hz:
        raise ConfigError(f"{source}: key 'rates.physics_hz': expected a multiple of "
                          f"rates.control_hz = {control_hz}, got {physics_hz}")
    return control_hz, physics_hz


def _trajectory(traj_t: Table, initial_p: Vec3, base: Path) -> TrajectoryConfig:
    """The `[trajectory]` table's keys for its kind."""
    k = TRAJECTORY_KEYS
    kind = k["kind"].read(traj_t)
    if kind == "hover":
        return TrajectoryConfig(kind=kind, position_enu_m=k["position_enu_m"].read(
            traj_t, initial_p))
    if kind == "mission":
        mission = (base / k["mission"].read(traj_t)).resolve()
        if not mission.is_file():
            raise traj_t.error("mission", f"a mission file (not found: {mission})")
        return TrajectoryConfig(kind=kind, position_enu_m=initial_p, mission_file=str(mission))
    traj = TrajectoryConfig(
        kind=kind,
        position_enu_m=k["position_enu_m"].read(traj_t, initial_p),
        rise_height_m=k["rise_height_m"].read(traj_t),
        rise_end_s=k["rise_end_s"].read(traj_t),
        figure_start_s=k["figure_start_s"].read(traj_t),
        figure_end_s=k["figure_end_s"].read(traj_t),
        amplitude_m=k["amplitude_m"].read(traj_t),
        axis_enu=k["axis_enu"].read(traj_t),
    )
    if not traj.rise_end_s <= traj.figure_start_s < traj.figure_end_s:
        raise traj_t.error("figure_end_s", "rise_end_s <= figure_start_s < figure_end_s")
    return traj


def _params(params_t: Table) -> dict[str, float]:
    """`[params]`: FCU parameter names and their values."""
    params: dict[str, float] = {}
    for name in list(params_t.data):
        if not (isinstance(name, str) and 0 < len(name) <= 16):
            raise params_t.error(name, "a parameter name of at most 16 characters")
        params[name] = replace(PARAMS_KEYS["*"], name=name).read(params_t)
    params_t.finish()
    return params


def scenario_from_data(data: dict[str, Any], path: str | Path, *,
                       firmware: bool = False) -> Scenario:
    """A scenario from its TOML data; file names are relative to `path`'s folder, and the
    vehicle and each gain set may be a file name or an inline table."""
    path = Path(path)
    source = str(path)
    t = Table(data, source)
    base = path.parent

    def rel(key: str, table: Table) -> Path:
        return (base / table.string(key)).resolve()

    def part(key: Key, table: Table, parse: Any, load: Any) -> tuple[Any, str]:
        """(a loader, the file or INLINE): files are read after the scenario's own keys
        are checked, so a scenario's own mistake is the one reported first."""
        value = key.read(table)
        if isinstance(value, dict):
            return (lambda: parse(value, f"{source}: table '{table.prefix}{key.name}'")), INLINE
        file = rel(key.name, table)
        return (lambda: load(file)), str(file)

    k = SCENARIO_KEYS
    vehicle_of, vehicle_path = part(k["vehicle"], t, parse_vehicle, load_vehicle)
    gains_t = k["gains"].read(t)
    pid_of, pid_path = part(GAINS_TABLE_KEYS["pid"], gains_t, parse_gains, load_gains)
    pd_of, pd_path = part(GAINS_TABLE_KEYS["pd"], gains_t, parse_gains, load_gains)
    gains_t.finish()

    control_hz, physics_hz = _rates(t, source)

    init = k["initial"].read(t)
    start = INITIAL_KEYS["start"].read(init)
    initial_p = INITIAL_KEYS["position_enu_m"].read(init)
    init.finish()

    traj_t = k["trajectory"].read(t)
    traj = _trajectory(traj_t, initial_p, base)
    traj_t.finish()

    dist = k["disturbance"].read(t)
    force_terms = parse_terms(DISTURBANCE_KEYS["force"].read(dist))
    torque_terms = parse_terms(DISTURBANCE_KEYS["torque"].read(dist))
    dist.finish()

    actuators = k["actuators"].read(t)
    ideal = ACTUATORS_KEYS["ideal"].read(actuators)
    actuators.finish()

    sensors = resolve_sensor_profile(k["sensors"].read(t), base) \
        if t.has("sensors") else None
    if sensors is not None and not firmware:  # what this FCU's link cannot take: refused
        check_servable(sensors, 1_000_000 // physics_hz, 1_000_000 // control_hz)
    params = _params(k["params"].read(t))
    sensor_faults = parse_sensor_faults(k["sensor_fault"].read(t))
    check_sensor_faults(sensor_faults, sensors, f"{source}: key 'sensor_fault'")
    actuator_faults = parse_actuator_faults(k["actuator_fault"].read(t), N_ROTORS)
    scenario = Scenario(
        name=k["name"].read(t),
        duration_s=k["duration_s"].read(t),
        controller=k["controller"].read(t),
        vehicle=vehicle_of(),
        gains_pid=pid_of(),
        gains_pd=pd_of(),
        control_rate_hz=control_hz,
        physics_rate_hz=physics_hz,
        ideal_actuators=ideal,
        ground_enabled=k["ground"].read(t, start == "ground"),
        start=start,
        initial_position_enu_m=initial_p,
        trajectory=traj,
        force_terms=force_terms,
        torque_terms=torque_terms,
        seed=k["seed"].read(t),
        # the range of the FCU's parameter COM_DIV_POS, which a run sets from this key
        divergence_position_m=k["divergence_position_m"].read(t),
        divergence_attitude_rad=k["divergence_attitude_rad"].read(t),
        divergence_attitude_hold_s=k["divergence_attitude_hold_s"].read(t),
        source=source,
        files={"scenario": str(path.resolve()), "vehicle": vehicle_path,
               "gains_pid": pid_path, "gains_pd": pd_path},
        sensors=sensors,
        params=params,
        sensor_faults=sensor_faults,
        actuator_faults=actuator_faults,
    )
    t.finish()
    if not scenario.gains_pd.is_pd:
        raise ConfigError(f"{pd_path}: the PD baseline (eq. 33) must have ki_r = ki_d = 0")
    return scenario
