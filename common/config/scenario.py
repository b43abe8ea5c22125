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
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from common.config.gains import Gains, check_stability, load_gains, parse_gains
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
    """[rates]: the control and physics rates (Hz), physics a multiple of control."""
    rates = t.table("rates", {})
    control_hz = rates.integer("control_hz", 500, lo=1, hi=1000)
    physics_hz = rates.integer("physics_hz", 1000, lo=1, hi=100000)
    rates.finish()
    if physics_hz % control_hz:
        raise ConfigError(f"{source}: key 'rates.physics_hz': expected a multiple of "
                          f"rates.control_hz = {control_hz}, got {physics_hz}")
    return control_hz, physics_hz


def _trajectory(traj_t: Table, initial_p: Vec3, base: Path) -> TrajectoryConfig:
    """[trajectory]: a hover, a mission file (relative to `base`) or a figure, checked."""
    kind = traj_t.string("kind", choices=TRAJECTORIES)
    if kind == "hover":
        traj = TrajectoryConfig(kind=kind, position_enu_m=traj_t.vec3("position_enu_m",
                                                                      initial_p))
    elif kind == "mission":
        mission = (base / traj_t.string("mission")).resolve()
        if not mission.is_file():
            raise traj_t.error("mission", f"a mission file (not found: {mission})")
        traj = TrajectoryConfig(kind=kind, position_enu_m=initial_p,
                                mission_file=str(mission))
    else:
        traj = TrajectoryConfig(
            kind=kind,
            position_enu_m=traj_t.vec3("position_enu_m", initial_p),
            rise_height_m=traj_t.number("rise_height_m", 5.0),
            rise_end_s=traj_t.number("rise_end_s", 10.0, lo=0.0, lo_open=True),
            figure_start_s=traj_t.number("figure_start_s", 20.0, lo=0.0),
            figure_end_s=traj_t.number("figure_end_s", 140.0, lo=0.0),
            amplitude_m=traj_t.number("amplitude_m", 5.0, lo=0.0),
            axis_enu=traj_t.vec3("axis_enu", (1.0, 2.0, 3.0)),
        )
        if not traj.rise_end_s <= traj.figure_start_s < traj.figure_end_s:
            raise traj_t.error("figure_end_s", "rise_end_s <= figure_start_s < figure_end_s")
    traj_t.finish()
    return traj


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

    def part(key: str, table: Table, parse: Any, load: Any) -> tuple[Any, str]:
        """(a loader, the file or INLINE): files are read after the scenario's own keys
        are checked, so a scenario's own mistake is the one reported first."""
        value = table.raw(key)
        if isinstance(value, dict):
            return (lambda: parse(value, f"{source}: table '{table.prefix}{key}'")), INLINE
        file = rel(key, table)
        return (lambda: load(file)), str(file)

    vehicle_of, vehicle_path = part("vehicle", t, parse_vehicle, load_vehicle)
    gains_t = t.table("gains")
    pid_of, pid_path = part("pid", gains_t, parse_gains, load_gains)
    pd_of, pd_path = part("pd", gains_t, parse_gains, load_gains)
    gains_t.finish()

    control_hz, physics_hz = _rates(t, source)

    init = t.table("initial")
    start = init.string("start", choices=STARTS)
    initial_p = init.vec3("position_enu_m", (0.0, 0.0, 0.0))
    init.finish()

    traj = _trajectory(t.table("trajectory"), initial_p, base)

    dist = t.table("disturbance", {})
    force_terms = parse_terms(dist.tables("force"))
    torque_terms = parse_terms(dist.tables("torque"))
    dist.finish()

    actuators = t.table("actuators", {})
    ideal = actuators.boolean("ideal", False)
    actuators.finish()

    sensors = resolve_sensor_profile(t.string("sensors", "truth"), base) \
        if t.has("sensors") else None
    if sensors is not None and not firmware:  # what this FCU's link cannot take: refused
        check_servable(sensors, 1_000_000 // physics_hz, 1_000_000 // control_hz)
    params_t = t.table("params", {})
    params: dict[str, float] = {}
    for name in list(params_t.data):
        if not (isinstance(name, str) and 0 < len(name) <= 16):
            raise params_t.error(name, "a parameter name of at most 16 characters")
        params[name] = params_t.number(name)
    params_t.finish()
    sensor_faults = parse_sensor_faults(t.tables("sensor_fault"))
    check_sensor_faults(sensor_faults, sensors, f"{source}: key 'sensor_fault'")
    actuator_faults = parse_actuator_faults(t.tables("actuator_fault"), N_ROTORS)
    scenario = Scenario(
        name=t.string("name"),
        duration_s=t.number("duration_s", lo=0.0, lo_open=True),
        controller=t.string("controller", "pid", choices=CONTROLLERS),
        vehicle=vehicle_of(),
        gains_pid=pid_of(),
        gains_pd=pd_of(),
        control_rate_hz=control_hz,
        physics_rate_hz=physics_hz,
        ideal_actuators=ideal,
        ground_enabled=t.boolean("ground", start == "ground"),
        start=start,
        initial_position_enu_m=initial_p,
        trajectory=traj,
        force_terms=force_terms,
        torque_terms=torque_terms,
        seed=t.integer("seed", 0, lo=0),
        # the range of the FCU's parameter COM_DIV_POS, which a run sets from this key
        divergence_position_m=t.number("divergence_position_m", 10.0, lo=0.1, hi=1000.0),
        divergence_attitude_rad=t.number("divergence_attitude_rad", DIVERGENCE_ATTITUDE_RAD,
                                         lo=0.1, hi=math.pi),
        divergence_attitude_hold_s=t.number("divergence_attitude_hold_s",
                                            DIVERGENCE_ATTITUDE_HOLD_S, lo=0.0, hi=60.0),
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
