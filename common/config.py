"""Typed configuration loaded from TOML: vehicle, gains and scenarios.

Every loader validates types, ranges, unknown and missing keys, and raises `ConfigError`
naming the file, the key and what was expected. Gains are checked against the
Routh-Hurwitz condition of the paper's eq. (20)-(23): k_p, k_d > 0, k_i >= 0, k_p k_d > k_i.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from common.vehicle_constants import N_ROTORS

if TYPE_CHECKING:
    from common.sensors_config import SensorProfile

Vec3 = tuple[float, float, float]


class ConfigError(ValueError):
    """A configuration file is unreadable, has a wrong type, a missing or unknown key."""


# ----------------------------------------------------------------------------------------
# Small typed readers over a TOML table
# ----------------------------------------------------------------------------------------


class _Table:
    """A TOML table that remembers where it came from, for error messages."""

    def __init__(self, data: dict[str, Any], source: str, prefix: str = "") -> None:
        self.data = data
        self.source = source
        self.prefix = prefix
        self.used: set[str] = set()

    def _name(self, key: str) -> str:
        return f"{self.prefix}{key}"

    def error(self, key: str, expected: str) -> ConfigError:
        got = self.data.get(key, "<missing>")
        return ConfigError(
            f"{self.source}: key '{self._name(key)}': expected {expected}, got {got!r}")

    def has(self, key: str) -> bool:
        return key in self.data

    def raw(self, key: str, default: Any = ...) -> Any:
        self.used.add(key)
        if key not in self.data:
            if default is ...:
                raise ConfigError(f"{self.source}: missing key '{self._name(key)}'")
            return default
        return self.data[key]

    def number(self, key: str, default: Any = ..., *, lo: float | None = None,
               hi: float | None = None, lo_open: bool = False) -> float:
        value = self.raw(key, default)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.error(key, "a number")
        value = float(value)
        bounds = f"[{lo if lo is not None else '-inf'}, {hi if hi is not None else 'inf'}]"
        if lo_open:
            bounds = "(" + bounds[1:]
        if not math.isfinite(value):
            raise self.error(key, f"a finite number in {bounds}")
        if lo is not None and (value < lo or (lo_open and value == lo)):
            raise self.error(key, f"a number in {bounds}")
        if hi is not None and value > hi:
            raise self.error(key, f"a number in {bounds}")
        return value

    def integer(self, key: str, default: Any = ..., *, lo: int | None = None,
                hi: int | None = None) -> int:
        value = self.raw(key, default)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(key, "an integer")
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            raise self.error(key, f"an integer in [{lo}, {hi}]")
        return value

    def boolean(self, key: str, default: Any = ...) -> bool:
        value = self.raw(key, default)
        if not isinstance(value, bool):
            raise self.error(key, "true or false")
        return value

    def string(self, key: str, default: Any = ..., *, choices: tuple[str, ...] = ()) -> str:
        value = self.raw(key, default)
        if not isinstance(value, str):
            raise self.error(key, "a string")
        if choices and value not in choices:
            raise self.error(key, "one of " + ", ".join(repr(c) for c in choices))
        return value

    def numbers(self, key: str, n: int, default: Any = ..., *, lo: float | None = None,
                hi: float | None = None, lo_open: bool = False) -> tuple[float, ...]:
        value = self.raw(key, default)
        ok = (isinstance(value, list | tuple) and len(value) == n
              and all(isinstance(v, int | float) and not isinstance(v, bool) for v in value))
        if not ok:
            raise self.error(key, f"a list of {n} numbers")
        out = tuple(float(v) for v in value)
        for v in out:
            if (not math.isfinite(v) or (lo is not None and (v < lo or (lo_open and v == lo)))
                    or (hi is not None and v > hi)):
                raise self.error(key, f"a list of {n} finite numbers in [{lo}, {hi}]")
        return out

    def table(self, key: str, default: Any = ...) -> _Table:
        value = self.raw(key, default)
        if not isinstance(value, dict):
            raise self.error(key, "a table")
        return _Table(value, self.source, f"{self._name(key)}.")

    def tables(self, key: str) -> list[_Table]:
        value = self.raw(key, [])
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise self.error(key, "an array of tables")
        return [_Table(v, self.source, f"{self._name(key)}[{i}].") for i, v in enumerate(value)]

    def finish(self) -> None:
        """Refuse keys this loader did not read (typos must not pass silently)."""
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            raise ConfigError(
                f"{self.source}: unknown key '{self._name(unknown[0])}' "
                f"(known: {', '.join(sorted(self.used))})")


def _read_toml(path: Path) -> dict[str, Any]:
    try:
        with path.open("rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ConfigError(f"{path}: file not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None


# ----------------------------------------------------------------------------------------
# Vehicle (MODEL.md section 1)
# ----------------------------------------------------------------------------------------



@dataclass(frozen=True)
class VehicleConfig:
    """Physical parameters of a tilt-rotor multirotor; body frame FLU, origin at the CoM."""

    name: str
    mass_kg: float
    inertia_diag_kg_m2: Vec3
    arm_length_m: float
    arm_azimuth_rad: tuple[float, ...]
    arm_elevation_rad: tuple[float, ...]
    spin: tuple[int, ...]
    thrust_coeff: float  # c_f, N s^2/rad^2
    drag_coeff: float  # c_d, N m s^2/rad^2
    rotor_speed_max_rad_s: float
    rotor_tau_up_s: float
    rotor_tau_down_s: float
    tilt_rate_max_rad_s: float
    gravity_m_s2: float = 9.81

    @property
    def n_rotors(self) -> int:
        return len(self.arm_azimuth_rad)


def parse_vehicle(data: dict[str, Any], source: str) -> VehicleConfig:
    t = _Table(data, source)
    name = t.string("name")
    mass = t.number("mass_kg", lo=0.0, lo_open=True)
    inertia = t.numbers("inertia_diag_kg_m2", 3, lo=0.0, lo_open=True)
    arm = t.number("arm_length_m", lo=0.0, lo_open=True)
    n = t.integer("n_rotors")
    if n != N_ROTORS:
        raise ConfigError(
            f"{source}: key 'n_rotors': expected {N_ROTORS}, got {n!r}: hexarotor only "
            f"(the logs and the simulator link carry six rotor speeds and six tilts)")
    if t.has("arm_azimuth_deg"):
        azimuth = tuple(math.radians(v) for v in t.numbers("arm_azimuth_deg", n))
    else:
        # The paper's gamma_i = pi/3 i - pi/6 generalised to n arms.
        azimuth = tuple(2.0 * math.pi * (i + 1) / n - math.pi / n for i in range(n))
    elevation = t.numbers("arm_elevation_rad", n, lo=-math.pi / 2, hi=math.pi / 2)
    spin_raw = t.raw("spin")
    if (not isinstance(spin_raw, list) or len(spin_raw) != n
            or any(s not in (1, -1) or isinstance(s, bool) for s in spin_raw)):
        raise t.error("spin", f"a list of {n} values, each +1 or -1")
    vehicle = VehicleConfig(
        name=name,
        mass_kg=mass,
        inertia_diag_kg_m2=inertia,  # type: ignore[arg-type]
        arm_length_m=arm,
        arm_azimuth_rad=azimuth,
        arm_elevation_rad=elevation,
        spin=tuple(int(s) for s in spin_raw),
        thrust_coeff=t.number("thrust_coeff", lo=0.0, lo_open=True),
        drag_coeff=t.number("drag_coeff", lo=0.0),
        rotor_speed_max_rad_s=t.number("rotor_speed_max_rad_s", lo=0.0, lo_open=True),
        rotor_tau_up_s=t.number("rotor_tau_up_s", lo=0.0, lo_open=True),
        rotor_tau_down_s=t.number("rotor_tau_down_s", lo=0.0, lo_open=True),
        tilt_rate_max_rad_s=t.number("tilt_rate_max_rad_s", lo=0.0, lo_open=True),
        gravity_m_s2=t.number("gravity_m_s2", 9.81, lo=0.0),
    )
    t.finish()
    return vehicle


def load_vehicle(path: str | Path) -> VehicleConfig:
    path = Path(path)
    return parse_vehicle(_read_toml(path), str(path))


# ----------------------------------------------------------------------------------------
# Gains (eq. 30 and eq. 33)
# ----------------------------------------------------------------------------------------

DAMPING_CHOICES = ("log_rate", "twist")


@dataclass(frozen=True)
class Gains:
    """Per-part gains of eq. (3): real part (attitude) and dual part (position), per axis.

    `damping` selects D in eq. (16): "log_rate" = 2 k_d . (ln q_e)' (the paper's PID law),
    "twist" = k_d . xi_e (Wang & Yu's damping, used by the PD baseline of eq. 33).
    """

    kp_r: Vec3
    kp_d: Vec3
    ki_r: Vec3
    ki_d: Vec3
    kd_r: Vec3
    kd_d: Vec3
    damping: str = "log_rate"

    @property
    def is_pd(self) -> bool:
        return not any(self.ki_r) and not any(self.ki_d)


GAIN_PARTS = ("kp_r", "kp_d", "ki_r", "ki_d", "kd_r", "kd_d")


def check_stability(gains: Gains) -> None:
    """Routh-Hurwitz for s^3 + k_d s^2 + k_p s + k_i per axis and part (eqs. 20-25)."""
    axes = "xyz"
    for part in ("r", "d"):
        kp = getattr(gains, f"kp_{part}")
        ki = getattr(gains, f"ki_{part}")
        kd = getattr(gains, f"kd_{part}")
        for a in range(3):
            tag = f"[{axes[a]}]"
            if not kp[a] > 0.0:
                raise ConfigError(f"gain kp_{part}{tag} = {kp[a]} violates k_p > 0")
            if not kd[a] > 0.0:
                raise ConfigError(f"gain kd_{part}{tag} = {kd[a]} violates k_d > 0")
            if not ki[a] >= 0.0:
                raise ConfigError(f"gain ki_{part}{tag} = {ki[a]} violates k_i >= 0")
            if not kp[a] * kd[a] > ki[a]:
                raise ConfigError(
                    f"gain ki_{part}{tag} = {ki[a]} violates k_p k_d > k_i "
                    f"(k_p k_d = {kp[a] * kd[a]})")


def parse_gains(data: dict[str, Any], source: str) -> Gains:
    t = _Table(data, source)
    values: dict[str, Any] = {}
    for key in GAIN_PARTS:
        default = (0.0, 0.0, 0.0) if key.startswith("ki") else ...
        values[key] = t.numbers(key, 3, default)
    gains = Gains(**values, damping=t.string("damping", "log_rate", choices=DAMPING_CHOICES))
    t.finish()
    try:
        check_stability(gains)
    except ConfigError as exc:
        raise ConfigError(f"{source}: {exc}") from None
    return gains


def load_gains(path: str | Path) -> Gains:
    path = Path(path)
    return parse_gains(_read_toml(path), str(path))


# ----------------------------------------------------------------------------------------
# Scenarios (MODEL.md section 5)
# ----------------------------------------------------------------------------------------

CONTROLLERS = ("pid", "pd")
TRAJECTORIES = ("case1_figure8", "hover", "mission")
STARTS = ("ground", "hover")
PROFILE_KINDS = ("pulse", "sine")


@dataclass(frozen=True)
class DisturbanceTerm:
    """One body-frame (FLU) disturbance term, per axis.

    pulse: amplitude while start_s <= t < end_s; sine: amplitude sin(omega t + phase) for
    t >= start_s (and t < end_s when end_s is finite).
    """

    kind: str
    amplitude: Vec3
    start_s: float = 0.0
    end_s: float = math.inf
    omega_rad_s: float = 0.0
    phase_rad: float = 0.0


def direction_flu(azimuth_deg: float, elevation_deg: float) -> Vec3:
    """Unit vector in FLU at an azimuth from +x towards +y and an elevation towards +z."""
    az, el = math.radians(azimuth_deg), math.radians(elevation_deg)
    return (math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el))


ACTUATOR_FAULT_KINDS = ("rotor_off", "rotor_stuck", "tilt_stuck", "tilt_off")


@dataclass(frozen=True)
class ActuatorFault:
    """One actuator failing at a time of the scenario clock (sitl/actuator_faults.py).

    rotor_off: the rotor's speed command is 0 (it spins down with its lag); rotor_stuck: the
    rotor keeps the speed it had at start_s; tilt_stuck: the servo keeps the tilt it had at
    start_s; tilt_off: the servo is unpowered, and as the plant has no dynamics about the
    tilt axis (MODEL.md 2: a kinematic, rate-limited servo) it stays where it stopped, as
    tilt_stuck does. From start_s until end_s (for ever by default).
    """

    kind: str
    index: int  # rotor / servo 0..n-1
    start_s: float
    end_s: float = math.inf

    def active(self, t_s: float) -> bool:
        return self.start_s <= t_s < self.end_s


SENSOR_FAULT_KINDS = ("mocap_off", "gyro_bias_step", "imu_nan", "pose_nan")


@dataclass(frozen=True)
class SensorFault:
    """One injected sensor fault, times counted from the flight's start (the scenario clock).

    mocap_off: no pose captured while start_s <= t < end_s; gyro_bias_step: `amplitude`
    (rad/s, FLU) added to the gyro from start_s on (until end_s, if given); imu_nan: the IMU
    samples of the window carry NaN in the gyro and the accelerometer; pose_nan: the poses
    captured in the window carry NaN.
    """

    kind: str
    start_s: float
    end_s: float = math.inf
    amplitude: Vec3 = (0.0, 0.0, 0.0)

    def active(self, t_s: float) -> bool:
        return self.start_s <= t_s < self.end_s


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
    source: str = ""
    files: dict[str, str] = field(default_factory=dict)
    # The simulated sensors (config/sensors/): None or a kind "truth" profile means the
    # exact state on the wire and no estimator (DESIGN.md section 3).
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


def _parse_terms(tables: list[_Table]) -> tuple[DisturbanceTerm, ...]:
    terms = []
    for t in tables:
        kind = t.string("kind", choices=PROFILE_KINDS)
        term = DisturbanceTerm(
            kind=kind,
            amplitude=_amplitude(t),
            start_s=t.number("start_s", 0.0, lo=0.0),
            end_s=t.number("end_s", math.inf) if t.has("end_s") else math.inf,
            omega_rad_s=t.number("omega_rad_s", 0.0) if kind == "sine" else 0.0,
            phase_rad=t.number("phase_rad", 0.0) if kind == "sine" else 0.0,
        )
        if kind == "pulse" and not math.isfinite(term.end_s):
            raise t.error("end_s", "a finite end time for a pulse")
        if term.end_s <= term.start_s:
            raise t.error("end_s", f"a time after start_s = {term.start_s}")
        t.finish()
        terms.append(term)
    return tuple(terms)


def _amplitude(t: _Table) -> Vec3:
    """A term's per-axis amplitude: `amplitude = [x, y, z]`, or `magnitude` along a direction
    given as `direction_flu = [x, y, z]` (normalised) or `azimuth_deg` and `elevation_deg`
    (`direction_flu`; for sweeps of a disturbance's size and direction)."""
    if not t.has("magnitude"):
        a = t.numbers("amplitude", 3)
        return (a[0], a[1], a[2])
    if t.has("amplitude"):
        raise t.error("magnitude", "either 'amplitude' or 'magnitude' (with a direction), "
                      "not both")
    magnitude = t.number("magnitude", lo=0.0)
    if t.has("direction_flu"):
        d = t.numbers("direction_flu", 3)
        n = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        if not n > 0.0:
            raise t.error("direction_flu", "a non-zero vector")
        u = (d[0] / n, d[1] / n, d[2] / n)
    else:
        u = direction_flu(t.number("azimuth_deg", 0.0), t.number("elevation_deg", 0.0))
    return (magnitude * u[0], magnitude * u[1], magnitude * u[2])


def _parse_actuator_faults(tables: list[_Table], n_rotors: int) -> tuple[ActuatorFault, ...]:
    faults = []
    for t in tables:
        fault = ActuatorFault(
            kind=t.string("kind", choices=ACTUATOR_FAULT_KINDS),
            index=t.integer("index", lo=0, hi=n_rotors - 1),
            start_s=t.number("start_s", 0.0, lo=0.0),
            end_s=t.number("end_s") if t.has("end_s") else math.inf)
        if fault.end_s <= fault.start_s:
            raise t.error("end_s", f"a time after start_s = {fault.start_s}")
        t.finish()
        faults.append(fault)
    return tuple(faults)


def _parse_sensor_faults(tables: list[_Table]) -> tuple[SensorFault, ...]:
    faults = []
    for t in tables:
        kind = t.string("kind", choices=SENSOR_FAULT_KINDS)
        start_s = t.number("start_s", lo=0.0)
        if kind == "gyro_bias_step":
            end_s = t.number("end_s") if t.has("end_s") else math.inf
            amplitude = t.numbers("amplitude", 3)
        else:  # a window: both ends
            end_s = t.number("end_s")
            amplitude = (0.0, 0.0, 0.0)
        if end_s <= start_s:
            raise t.error("end_s", f"a time after start_s = {start_s}")
        t.finish()
        faults.append(SensorFault(kind, start_s, end_s,
                                  (amplitude[0], amplitude[1], amplitude[2])))
    return tuple(faults)


def check_sensor_faults(faults: tuple[SensorFault, ...], sensors: SensorProfile | None,
                        where: str) -> None:
    """Faults act on simulated sensors: refused with the exact state (no profile, truth)."""
    if faults and (sensors is None or sensors.is_truth):
        raise ConfigError(f"{where}: faults need a sensor profile (key 'sensors', not the "
                          f"exact state), got "
                          f"{'no sensors key' if sensors is None else repr(sensors.name)}")


INLINE = "<inline>"  # Scenario.files entry of a vehicle or gain table given in the scenario


def load_scenario(path: str | Path) -> Scenario:
    """Load a scenario and the vehicle and gain files it names (paths relative to it)."""
    path = Path(path)
    return scenario_from_data(_read_toml(path), path)


def resolved_scenario_data(path: str | Path) -> dict[str, Any]:
    """The scenario file as data with its vehicle and gain files inlined as tables and its
    other file references made absolute: one self-contained description of a run, which
    `scenario_from_data` loads exactly as `load_scenario` loads the file (campaigns set
    keys in it and hash it)."""
    path = Path(path)
    data = _read_toml(path)
    base = path.parent
    t = _Table(data, str(path))

    def inline(value: Any, key: str) -> Any:
        if isinstance(value, str):
            return _read_toml((base / value).resolve())
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


def scenario_from_data(data: dict[str, Any], path: str | Path) -> Scenario:
    """A scenario from its TOML data; file names are relative to `path`'s folder, and the
    vehicle and each gain set may be a file name or an inline table."""
    path = Path(path)
    source = str(path)
    t = _Table(data, source)
    base = path.parent

    def rel(key: str, table: _Table) -> Path:
        return (base / table.string(key)).resolve()

    def part(key: str, table: _Table, parse: Any, load: Any) -> tuple[Any, str]:
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

    rates = t.table("rates", {})
    control_hz = rates.integer("control_hz", 500, lo=1, hi=1000)
    physics_hz = rates.integer("physics_hz", 1000, lo=1, hi=100000)
    rates.finish()
    if physics_hz % control_hz:
        raise ConfigError(f"{source}: key 'rates.physics_hz': expected a multiple of "
                          f"rates.control_hz = {control_hz}, got {physics_hz}")

    init = t.table("initial")
    start = init.string("start", choices=STARTS)
    initial_p = init.numbers("position_enu_m", 3, (0.0, 0.0, 0.0))
    init.finish()

    traj_t = t.table("trajectory")
    kind = traj_t.string("kind", choices=TRAJECTORIES)
    if kind == "hover":
        traj = TrajectoryConfig(kind=kind, position_enu_m=traj_t.numbers(  # type: ignore[arg-type]
            "position_enu_m", 3, initial_p))
    elif kind == "mission":
        mission = rel("mission", traj_t)
        if not mission.is_file():
            raise traj_t.error("mission", f"a mission file (not found: {mission})")
        traj = TrajectoryConfig(kind=kind, position_enu_m=initial_p,  # type: ignore[arg-type]
                                mission_file=str(mission))
    else:
        traj = TrajectoryConfig(
            kind=kind,
            position_enu_m=traj_t.numbers("position_enu_m", 3, initial_p),  # type: ignore[arg-type]
            rise_height_m=traj_t.number("rise_height_m", 5.0),
            rise_end_s=traj_t.number("rise_end_s", 10.0, lo=0.0, lo_open=True),
            figure_start_s=traj_t.number("figure_start_s", 20.0, lo=0.0),
            figure_end_s=traj_t.number("figure_end_s", 140.0, lo=0.0),
            amplitude_m=traj_t.number("amplitude_m", 5.0, lo=0.0),
            axis_enu=traj_t.numbers("axis_enu", 3, (1.0, 2.0, 3.0)),  # type: ignore[arg-type]
        )
        if not traj.rise_end_s <= traj.figure_start_s < traj.figure_end_s:
            raise traj_t.error("figure_end_s", "rise_end_s <= figure_start_s < figure_end_s")
    traj_t.finish()

    dist = t.table("disturbance", {})
    force_terms = _parse_terms(dist.tables("force"))
    torque_terms = _parse_terms(dist.tables("torque"))
    dist.finish()

    actuators = t.table("actuators", {})
    ideal = actuators.boolean("ideal", False)
    actuators.finish()

    from common.sensors_config import check_servable, resolve_sensor_profile

    sensors = resolve_sensor_profile(t.string("sensors", "truth"), base) \
        if t.has("sensors") else None
    if sensors is not None:  # what the plant cannot serve at these rates: refused here
        check_servable(sensors, 1_000_000 // physics_hz, 1_000_000 // control_hz)
    params_t = t.table("params", {})
    params: dict[str, float] = {}
    for name in list(params_t.data):
        if not (isinstance(name, str) and 0 < len(name) <= 16):
            raise params_t.error(name, "a parameter name of at most 16 characters")
        params[name] = params_t.number(name)
    params_t.finish()
    sensor_faults = _parse_sensor_faults(t.tables("sensor_fault"))
    check_sensor_faults(sensor_faults, sensors, f"{source}: key 'sensor_fault'")
    actuator_faults = _parse_actuator_faults(t.tables("actuator_fault"), N_ROTORS)
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
        initial_position_enu_m=initial_p,  # type: ignore[arg-type]
        trajectory=traj,
        force_terms=force_terms,
        torque_terms=torque_terms,
        seed=t.integer("seed", 0, lo=0),
        # the range of the FCU's parameter COM_DIV_POS, which a run sets from this key
        divergence_position_m=t.number("divergence_position_m", 10.0, lo=0.1, hi=1000.0),
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
