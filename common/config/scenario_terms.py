"""The time-tabled parts of a scenario (docs/model.md#scenarios), read from its TOML tables:
body-frame disturbance terms ([disturbance]), actuator faults ([[actuator_fault]]) and
sensor faults ([[sensor_fault]]), each checked by `common.config.reader`."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from common.config.keys import REQUIRED, Key, KeyTable
from common.config.reader import ConfigError, Table
from common.config.sensors import SensorProfile
from common.vehicle_constants import N_ROTORS

Vec3 = tuple[float, float, float]

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
    tilt axis (docs/model.md#plant: a kinematic, rate-limited servo) it stays where it stopped, as
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


TERM_KEYS = KeyTable("disturbance.force[]", (
    Key("kind", "string", "`pulse`: `amplitude` while start_s <= t < end_s; `sine`: "
        "`amplitude` sin(omega t + phase) from start_s", choices=PROFILE_KINDS),
    Key("amplitude", "numbers", "per axis, body frame (FLU)", "N or N m",
        default_doc="required unless `magnitude`"),
    Key("magnitude", "number", "instead of `amplitude`: the size along a direction", "N or N m",
        lo=0.0, default_doc="none"),
    Key("direction_flu", "numbers", "with `magnitude`: the direction (normalised, not zero)",
        default_doc="from the angles"),
    Key("azimuth_deg", "number", "with `magnitude` and no `direction_flu`: from +x towards +y",
        "deg", 0.0),
    Key("elevation_deg", "number", "with `magnitude` and no `direction_flu`: towards +z",
        "deg", 0.0),
    Key("start_s", "number", "the term's start (scenario clock)", "s", 0.0, lo=0.0),
    Key("end_s", "number", "the term's end; a pulse needs a finite one", "s", math.inf,
        default_doc="for ever", range_doc="> start_s"),
    Key("omega_rad_s", "number", "a sine's angular frequency", "rad/s", 0.0),
    Key("phase_rad", "number", "a sine's phase", "rad", 0.0),
), also=("disturbance.torque[]",))

ACTUATOR_FAULT_KEYS = KeyTable("actuator_fault[]", (
    Key("kind", "string", "`rotor_off`: commanded 0, spins down with its lag; `rotor_stuck`: "
        "keeps its speed; `tilt_stuck`: keeps its tilt; `tilt_off`: unpowered, stays where "
        "it stopped", choices=ACTUATOR_FAULT_KINDS),
    Key("index", "integer", "the rotor or tilt servo", lo=0, hi=N_ROTORS - 1),
    Key("start_s", "number", "when it fails (scenario clock)", "s", 0.0, lo=0.0),
    Key("end_s", "number", "when it works again", "s", math.inf, default_doc="for ever",
        range_doc="> start_s"),
))

SENSOR_FAULT_KEYS = KeyTable("sensor_fault[]", (
    Key("kind", "string", "`mocap_off`: no pose captured; `imu_nan`, `pose_nan`: the "
        "window's samples carry NaN; `gyro_bias_step`: `amplitude` added to the gyro",
        choices=SENSOR_FAULT_KINDS),
    Key("start_s", "number", "the fault's start (scenario clock)", "s", lo=0.0),
    Key("end_s", "number", "the fault's end", "s", math.inf, range_doc="> start_s",
        default_doc="`gyro_bias_step`: for ever; the others: required"),
    Key("amplitude", "numbers", "`gyro_bias_step` only: the bias step, FLU", "rad/s",
        default_doc="required for `gyro_bias_step`"),
), "Faults need a sensor profile (key `sensors`, not the exact state).")


def parse_terms(tables: list[Table]) -> tuple[DisturbanceTerm, ...]:
    terms = []
    k = TERM_KEYS
    for t in tables:
        kind = k["kind"].read(t)
        term = DisturbanceTerm(
            kind=kind,
            amplitude=_amplitude(t),
            start_s=k["start_s"].read(t),
            end_s=k["end_s"].read(t) if t.has("end_s") else math.inf,
            omega_rad_s=k["omega_rad_s"].read(t) if kind == "sine" else 0.0,
            phase_rad=k["phase_rad"].read(t) if kind == "sine" else 0.0,
        )
        if kind == "pulse" and not math.isfinite(term.end_s):
            raise t.error("end_s", "a finite end time for a pulse")
        if term.end_s <= term.start_s:
            raise t.error("end_s", f"a time after start_s = {term.start_s}")
        t.finish()
        terms.append(term)
    return tuple(terms)


def _amplitude(t: Table) -> Vec3:
    """A term's per-axis amplitude: `amplitude = [x, y, z]`, or `magnitude` along a direction
    given as `direction_flu = [x, y, z]` (normalised) or `azimuth_deg` and `elevation_deg`
    (`direction_flu`; for sweeps of a disturbance's size and direction)."""
    k = TERM_KEYS
    if not t.has("magnitude"):
        a = k["amplitude"].read(t, REQUIRED)
        return (a[0], a[1], a[2])
    if t.has("amplitude"):
        raise t.error("magnitude", "either 'amplitude' or 'magnitude' (with a direction), "
                      "not both")
    magnitude = k["magnitude"].read(t, REQUIRED)
    if t.has("direction_flu"):
        d = k["direction_flu"].read(t, REQUIRED)
        n = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        if not n > 0.0:
            raise t.error("direction_flu", "a non-zero vector")
        u = (d[0] / n, d[1] / n, d[2] / n)
    else:
        u = direction_flu(k["azimuth_deg"].read(t), k["elevation_deg"].read(t))
    return (magnitude * u[0], magnitude * u[1], magnitude * u[2])


def parse_actuator_faults(tables: list[Table], n_rotors: int) -> tuple[ActuatorFault, ...]:
    faults = []
    k = ACTUATOR_FAULT_KEYS
    index = replace(k["index"], hi=n_rotors - 1)
    for t in tables:
        fault = ActuatorFault(
            kind=k["kind"].read(t),
            index=index.read(t),
            start_s=k["start_s"].read(t),
            end_s=k["end_s"].read(t, REQUIRED) if t.has("end_s") else math.inf)
        if fault.end_s <= fault.start_s:
            raise t.error("end_s", f"a time after start_s = {fault.start_s}")
        t.finish()
        faults.append(fault)
    return tuple(faults)


def parse_sensor_faults(tables: list[Table]) -> tuple[SensorFault, ...]:
    faults = []
    k = SENSOR_FAULT_KEYS
    for t in tables:
        kind = k["kind"].read(t)
        start_s = k["start_s"].read(t)
        if kind == "gyro_bias_step":
            end_s = k["end_s"].read(t, REQUIRED) if t.has("end_s") else math.inf
            amplitude = k["amplitude"].read(t, REQUIRED)
        else:  # a window: both ends
            end_s = k["end_s"].read(t, REQUIRED)
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
