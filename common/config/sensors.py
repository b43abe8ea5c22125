"""Typed sensor profiles (IMU, barometer, magnetometer, motion capture) loaded from TOML.

Same rules as `common.config.scenario` (the reader of `common.config.reader`): every key is required
and checked (type, finite, range), unknown keys are refused, and errors are `ConfigError`
naming the file and the key.
Units are SI and in the key names; frames are in the key names (NED earth field).
`kind = "truth"` declares a perfect profile and then requires every noise, bias, latency
and dropout figure to be zero.

Timing: sensor k is sampled at k / rate_hz on the simulation clock (`period_us`, exact), each
section may add a timing jitter (`jitter_s`, optional, below half its period), and what the
plant cannot serve at a scenario's physics step and control period is refused by
`check_servable` when the scenario and the profile meet, before anything runs. The loader
takes an IMU from PROFILE_IMU_RATE_MIN_HZ (100 Hz, what PX4's simulator link serves);
this project's own FCU link needs IMU_RATE_MIN_HZ (500 Hz), checked by `check_servable`.

The `[gps]` section is optional (absent: an exact fix); only PX4's link sends GPS.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from fractions import Fraction
from pathlib import Path
from typing import Any

from common.config.keys import REQUIRED, Key, KeyTable
from common.config.reader import ConfigError, Table, read_toml

Vec3 = tuple[float, float, float]

RATE_MIN_HZ = 1.0
RATE_MAX_HZ = 10000.0
PROFILE_IMU_RATE_MIN_HZ = 100.0  # what the loader takes (sitl --protocol px4-hil)
IMU_RATE_MIN_HZ = 500.0  # what this project's FCU link needs (check_servable)
KINDS = ("truth", "model")


@dataclass(frozen=True)
class GyroConfig:
    noise_density_rad_s_sqrt_hz: float  # white noise density N (datasheet)
    turn_on_bias_sigma_rad_s: float  # sigma of the constant drawn at start
    bias_random_walk_rad_s2_sqrt_hz: float  # sigma_rw: bias += sigma_rw sqrt(dt) n
    range_rad_s: float  # saturation, per axis
    # The bias's correlation time (optional key): None, an unbounded random walk; else a
    # first-order Gauss-Markov process of that time constant driven by sigma_rw (sitl.sensors).
    bias_correlation_time_s: float | None = None


@dataclass(frozen=True)
class AccelConfig:
    noise_density_m_s2_sqrt_hz: float
    turn_on_bias_sigma_m_s2: float
    bias_random_walk_m_s3_sqrt_hz: float
    range_m_s2: float
    bias_correlation_time_s: float | None = None  # as the gyro's
    # The ground contact's impulse as the accelerometer reports it (optional key): 0, within
    # the IMU sample that holds the touchdown's physics step (its size may exceed the range
    # and clip); > 0, spread evenly over this long from that sample on, the integral kept.
    contact_spread_s: float = 0.0


@dataclass(frozen=True)
class ImuConfig:
    rate_hz: float  # 100..10000 (this project's FCU: 500..10000)
    vibration_factor: float  # multiplies both white noise densities
    gyro: GyroConfig
    accel: AccelConfig
    jitter_s: float = 0.0  # sampling instants uniform within +-jitter_s of k / rate_hz

    @property
    def gyro_sigma_rad_s(self) -> float:
        """White noise per sample: vibration_factor * N * sqrt(rate) (docs/estimator.md:
        the profiles and their sources)."""
        return self.vibration_factor * self.gyro.noise_density_rad_s_sqrt_hz * \
            math.sqrt(self.rate_hz)

    @property
    def accel_sigma_m_s2(self) -> float:
        return self.vibration_factor * self.accel.noise_density_m_s2_sqrt_hz * \
            math.sqrt(self.rate_hz)


@dataclass(frozen=True)
class BaroConfig:
    rate_hz: float
    noise_m: float  # sigma of pressure altitude per sample
    bias_m: float  # constant offset (optional key, default 0)
    jitter_s: float = 0.0


@dataclass(frozen=True)
class MagConfig:
    rate_hz: float
    field_ned_gauss: Vec3  # fixed earth field in NED
    noise_gauss: float  # sigma per axis per sample
    jitter_s: float = 0.0


@dataclass(frozen=True)
class MocapConfig:
    rate_hz: float
    position_noise_m: float  # sigma per axis
    attitude_noise_rad: float  # sigma per axis of the small body-frame rotation
    latency_s: float  # capture at t is delivered at t + latency (any float >= 0)
    dropout_probability: float  # per capture, 0..1
    jitter_s: float = 0.0


@dataclass(frozen=True)
class GpsConfig:
    """A GNSS fix's white noise per fix and the accuracy it reports (PX4's link only)."""

    position_noise_m: float  # sigma per horizontal axis
    altitude_noise_m: float
    velocity_noise_ned_m_s: Vec3  # sigma per NED axis
    eph_m: float  # the reported accuracies
    epv_m: float
    satellites: int


EXACT_GPS = GpsConfig(0.0, 0.0, (0.0, 0.0, 0.0), 1.0, 1.0, 10)


@dataclass(frozen=True)
class SensorProfile:
    name: str
    kind: str  # "truth" or "model"
    imu: ImuConfig
    baro: BaroConfig
    mag: MagConfig
    mocap: MocapConfig
    source: str = ""  # the file it was read from
    gps: GpsConfig = EXACT_GPS

    @property
    def is_truth(self) -> bool:
        return self.kind == "truth"


SECTIONS = ("imu", "baro", "mag", "mocap")


# ------------------------------------------------------------------ the keys

def _rate_key(lo: float = RATE_MIN_HZ) -> Key:
    return Key("rate_hz", "number", "the sampling rate: sample k at k / rate_hz", "Hz",
               lo=lo, hi=RATE_MAX_HZ)


_JITTER = Key("jitter_s", "number", "each sampling instant uniform within +-jitter_s", "s",
              0.0, lo=0.0, range_doc="below half the period")


def _sigma(name: str, meaning: str, unit: str, default: Any = REQUIRED) -> Key:
    return Key(name, "number", meaning, unit, default, lo=0.0)


def _bias_keys(turn_on: str, unit: str, rw_name: str, rw_unit: str) -> tuple[Key, ...]:
    return (
        _sigma(turn_on, "sigma of the constant bias drawn at start", unit),
        _sigma(rw_name, "sigma_rw: bias += sigma_rw sqrt(dt) n", rw_unit),
        Key("bias_correlation_time_s", "number", "the bias's correlation time: a first-order "
            "Gauss-Markov process driven by sigma_rw", "s", lo=0.0, lo_open=True,
            default_doc="none: an unbounded random walk"))


PROFILE_KEYS = KeyTable("", (
    Key("name", "string", "the profile's name"),
    Key("kind", "string", "`truth`: a perfect profile (every noise, bias, latency, dropout "
        "and jitter figure 0); `model`: modelled sensors", choices=KINDS),
    Key("imu", "table", "the IMU (`[imu]`)"),
    Key("baro", "table", "the barometer (`[baro]`)"),
    Key("mag", "table", "the magnetometer (`[mag]`)"),
    Key("mocap", "table", "the motion capture (`[mocap]`)"),
    Key("gps", "table", "GNSS, sent on PX4's link only (`[gps]`)", default_doc="an exact fix"),
))

IMU_KEYS = KeyTable("imu", (
    _rate_key(PROFILE_IMU_RATE_MIN_HZ),
    _sigma("vibration_factor", "multiplies both white noise densities", ""),
    Key("gyro", "table", "the gyro (`[imu.gyro]`)"),
    Key("accel", "table", "the accelerometer (`[imu.accel]`)"),
    _JITTER,
), f"This project's FCU needs an IMU from {IMU_RATE_MIN_HZ:g} Hz, with a sample at the end of "
   "every control period and no jitter; firmware served by `sitl --protocol` takes it from "
   f"{PROFILE_IMU_RATE_MIN_HZ:g} Hz.")

GYRO_KEYS = KeyTable("imu.gyro", (
    _sigma("noise_density_rad_s_sqrt_hz", "white noise density N (datasheet)",
           "rad/s/sqrt(Hz)"),
    *_bias_keys("turn_on_bias_sigma_rad_s", "rad/s", "bias_random_walk_rad_s2_sqrt_hz",
                "rad/s^2/sqrt(Hz)"),
    Key("range_rad_s", "number", "saturation, per axis", "rad/s", lo=0.0, lo_open=True),
))

ACCEL_KEYS = KeyTable("imu.accel", (
    _sigma("noise_density_m_s2_sqrt_hz", "white noise density N (datasheet)",
           "m/s^2/sqrt(Hz)"),
    *_bias_keys("turn_on_bias_sigma_m_s2", "m/s^2", "bias_random_walk_m_s3_sqrt_hz",
                "m/s^3/sqrt(Hz)"),
    Key("range_m_s2", "number", "saturation, per axis", "m/s^2", lo=0.0, lo_open=True),
    Key("contact_spread_s", "number", "a ground contact's impulse spread over this long (0: "
        "within one sample)", "s", 0.0, lo=0.0, hi=1.0),
))

BARO_KEYS = KeyTable("baro", (
    _rate_key(),
    _sigma("noise_m", "sigma of the pressure altitude per sample", "m"),
    Key("bias_m", "number", "constant offset", "m", 0.0),
    _JITTER,
), "Not faster than the IMU (its samples ride on the IMU's).")

MAG_KEYS = KeyTable("mag", (
    Key("field_ned_gauss", "numbers", "the fixed earth field (NED)", "gauss"),
    _rate_key(),
    _sigma("noise_gauss", "sigma per axis per sample", "gauss"),
    _JITTER,
), "Not faster than the IMU.")

MOCAP_KEYS = KeyTable("mocap", (
    _rate_key(),
    _sigma("position_noise_m", "sigma per axis", "m"),
    _sigma("attitude_noise_rad", "sigma per axis of the small body-frame rotation", "rad"),
    _sigma("latency_s", "a capture at t is delivered at t + latency", "s"),
    Key("dropout_probability", "number", "the chance a capture is lost", lo=0.0, hi=1.0),
    _JITTER,
))

GPS_KEYS = KeyTable("gps", (
    Key("velocity_noise_ned_m_s", "numbers", "sigma per NED axis", "m/s", lo=0.0),
    Key("satellites", "number", "the satellites reported", lo=0.0, hi=255.0,
        range_doc="whole"),
    _sigma("position_noise_m", "sigma per horizontal axis", "m"),
    _sigma("altitude_noise_m", "sigma of the altitude", "m"),
    Key("eph_m", "number", "the horizontal accuracy reported", "m", lo=0.0, hi=655.0),
    Key("epv_m", "number", "the vertical accuracy reported", "m", lo=0.0, hi=655.0),
))


def period_us(rate_hz: float) -> Fraction:
    """The exact sample period in microseconds (the float rate taken as it is stored)."""
    return Fraction(1_000_000) / Fraction(rate_hz)


def _jitter(t: Table, rate_hz: float) -> float:
    """`jitter_s` (optional, 0): at least 0 and below half the period, so that the samples
    keep their order."""
    jitter: float = _JITTER.read(t)
    half_s = 0.5 / rate_hz
    if not jitter < half_s:
        raise ConfigError(f"{t.source}: {t.prefix}jitter_s = {jitter:g} is not below half "
                          f"the sample period ({half_s:g} s at {rate_hz:g} Hz)")
    return jitter


def _read(keys: KeyTable, t: Table, *names: str) -> list[Any]:
    """The named keys of `t`, in that order."""
    return [keys[n].read(t) for n in names]


def _correlation_time(keys: KeyTable, t: Table) -> float | None:
    """`bias_correlation_time_s` (optional; absent: an unbounded random walk), > 0."""
    if not t.has("bias_correlation_time_s"):
        return None
    value: float = keys["bias_correlation_time_s"].read(t)
    return value


def _parse_imu(t: Table) -> ImuConfig:
    rate, vib = _read(IMU_KEYS, t, "rate_hz", "vibration_factor")
    g = IMU_KEYS["gyro"].read(t)
    density, turn_on, walk, span = _read(
        GYRO_KEYS, g, "noise_density_rad_s_sqrt_hz", "turn_on_bias_sigma_rad_s",
        "bias_random_walk_rad_s2_sqrt_hz", "range_rad_s")
    gyro = GyroConfig(density, turn_on, walk, span,
                      bias_correlation_time_s=_correlation_time(GYRO_KEYS, g))
    g.finish()
    a = IMU_KEYS["accel"].read(t)
    density, turn_on, walk, span = _read(
        ACCEL_KEYS, a, "noise_density_m_s2_sqrt_hz", "turn_on_bias_sigma_m_s2",
        "bias_random_walk_m_s3_sqrt_hz", "range_m_s2")
    accel = AccelConfig(density, turn_on, walk, span,
                        bias_correlation_time_s=_correlation_time(ACCEL_KEYS, a),
                        contact_spread_s=ACCEL_KEYS["contact_spread_s"].read(a))
    a.finish()
    jitter = _jitter(t, rate)
    t.finish()
    return ImuConfig(rate_hz=rate, vibration_factor=vib, gyro=gyro, accel=accel,
                     jitter_s=jitter)


def _parse_baro(t: Table) -> BaroConfig:
    rate, noise, bias = _read(BARO_KEYS, t, "rate_hz", "noise_m", "bias_m")
    out = BaroConfig(rate_hz=rate, noise_m=noise, bias_m=bias, jitter_s=_jitter(t, rate))
    t.finish()
    return out


def _parse_mag(t: Table) -> MagConfig:
    field_ned, rate, noise = _read(MAG_KEYS, t, "field_ned_gauss", "rate_hz", "noise_gauss")
    out = MagConfig(rate_hz=rate, field_ned_gauss=(field_ned[0], field_ned[1], field_ned[2]),
                    noise_gauss=noise, jitter_s=_jitter(t, rate))
    t.finish()
    return out


def _parse_mocap(t: Table) -> MocapConfig:
    rate, position, attitude, latency, dropout = _read(
        MOCAP_KEYS, t, "rate_hz", "position_noise_m", "attitude_noise_rad", "latency_s",
        "dropout_probability")
    out = MocapConfig(rate, position, attitude, latency, dropout, jitter_s=_jitter(t, rate))
    t.finish()
    return out


def _parse_gps(t: Table) -> GpsConfig:
    vel, sats = _read(GPS_KEYS, t, "velocity_noise_ned_m_s", "satellites")
    if sats != int(sats):
        raise ConfigError(f"{t.source}: key '{t.prefix}satellites': expected a whole number, "
                          f"got {sats!r}")
    pos, alt, eph, epv = _read(GPS_KEYS, t, "position_noise_m", "altitude_noise_m", "eph_m",
                               "epv_m")
    out = GpsConfig(position_noise_m=pos, altitude_noise_m=alt,
                    velocity_noise_ned_m_s=(vel[0], vel[1], vel[2]),
                    eph_m=eph, epv_m=epv, satellites=int(sats))
    t.finish()
    return out


def _check_rates(p: SensorProfile, source: str) -> None:
    """Magnetometer and barometer ride on the IMU's HIL_SENSOR: not faster than the IMU."""
    for section in ("baro", "mag"):
        rate = getattr(p, section).rate_hz
        if rate > p.imu.rate_hz:
            raise ConfigError(f"{source}: {section}.rate_hz = {rate:g} is faster than "
                              f"imu.rate_hz = {p.imu.rate_hz:g} (its samples are sent with "
                              f"the IMU's)")


def check_servable(p: SensorProfile, physics_dt_us: int, control_dt_us: int, *,
                   imu_rate_min_hz: float = IMU_RATE_MIN_HZ) -> None:
    """Refuse (ConfigError naming the file and the key) what the plant cannot serve at this
    physics step and control period: an IMU slower than `imu_rate_min_hz` (this project's
    FCU link: 500 Hz), a sensor faster than the physics step, an IMU without a sample at
    the end of every control period (its sample there drives the FCU's control step and
    the lockstep), a jittered IMU (for the same reason). The truth profile is not sampled
    by this project's link (the exact state is sent): nothing to check there."""
    src = p.source or repr(p.name)
    if p.is_truth and imu_rate_min_hz == IMU_RATE_MIN_HZ:
        return
    if p.imu.rate_hz < imu_rate_min_hz:
        raise ConfigError(f"{src}: imu.rate_hz = {p.imu.rate_hz:g} is below "
                          f"{imu_rate_min_hz:g} Hz, the slowest IMU this link serves")
    for section in SECTIONS:
        rate = getattr(p, section).rate_hz
        if period_us(rate) < physics_dt_us:
            raise ConfigError(f"{src}: {section}.rate_hz = {rate:g} is faster than the "
                              f"physics step allows ({physics_dt_us} us: at most "
                              f"{1e6 / physics_dt_us:g} Hz)")
    per_period = Fraction(control_dt_us) / period_us(p.imu.rate_hz)
    if per_period.denominator != 1:
        raise ConfigError(f"{src}: imu.rate_hz = {p.imu.rate_hz:g} puts no sample at the end "
                          f"of every {control_dt_us} us control period (the IMU drives the "
                          f"control loop: a multiple of {1e6 / control_dt_us:g} Hz)")
    if p.imu.jitter_s > 0.0:
        raise ConfigError(f"{src}: imu.jitter_s = {p.imu.jitter_s:g}: the IMU's sample at "
                          f"the end of each control period drives the control loop and "
                          f"cannot move off it")


# Fields that a `kind = "truth"` profile must hold at zero (section, field).
_TRUTH_ZERO = (
    ("imu.gyro", "noise_density_rad_s_sqrt_hz"), ("imu.gyro", "turn_on_bias_sigma_rad_s"),
    ("imu.gyro", "bias_random_walk_rad_s2_sqrt_hz"),
    ("imu.accel", "noise_density_m_s2_sqrt_hz"), ("imu.accel", "turn_on_bias_sigma_m_s2"),
    ("imu.accel", "bias_random_walk_m_s3_sqrt_hz"),
    ("baro", "noise_m"), ("baro", "bias_m"), ("mag", "noise_gauss"),
    ("mocap", "position_noise_m"), ("mocap", "attitude_noise_rad"), ("mocap", "latency_s"),
    ("mocap", "dropout_probability"), ("imu", "jitter_s"), ("baro", "jitter_s"),
    ("mag", "jitter_s"), ("mocap", "jitter_s"),
)


def _check_truth(p: SensorProfile, source: str) -> None:
    for section, key in _TRUTH_ZERO:
        obj: Any = p
        for part in section.split("."):
            obj = getattr(obj, part)
        assert key in {f.name for f in fields(obj)}
        if getattr(obj, key) != 0.0:
            raise ConfigError(f"{source}: key '{section}.{key}': expected 0 in a "
                              f"kind = \"truth\" profile, got {getattr(obj, key)!r}")
    g = p.gps
    if g.position_noise_m or g.altitude_noise_m or any(g.velocity_noise_ned_m_s):
        raise ConfigError(f"{source}: section 'gps': expected no noise in a "
                          f"kind = \"truth\" profile")


def stale_sensors(p: SensorProfile) -> list[str]:
    """The sensors whose samples repeat exactly at rest (no white noise), which PX4's
    DataValidator declares stale (the same value within 1e-6 for 100 samples in a row,
    1,000 for the magnetometer)."""
    out = []
    if p.imu.accel_sigma_m_s2 == 0.0:
        out.append("accel")
    if p.imu.gyro_sigma_rad_s == 0.0:
        out.append("gyro")
    if p.baro.noise_m == 0.0:
        out.append("baro")
    if p.mag.noise_gauss == 0.0:
        out.append("mag")
    return out


def parse_sensor_profile(data: dict[str, Any], source: str) -> SensorProfile:
    t = Table(data, source)
    k = PROFILE_KEYS
    profile = SensorProfile(
        name=k["name"].read(t),
        kind=k["kind"].read(t),
        imu=_parse_imu(k["imu"].read(t)),
        baro=_parse_baro(k["baro"].read(t)),
        mag=_parse_mag(k["mag"].read(t)),
        mocap=_parse_mocap(k["mocap"].read(t)),
        source=source,
        gps=_parse_gps(k["gps"].read(t)) if t.has("gps") else EXACT_GPS)
    t.finish()
    if profile.is_truth:
        _check_truth(profile, source)
    _check_rates(profile, source)
    return profile


def load_sensor_profile(path: str | Path) -> SensorProfile:
    """Read and validate a sensor profile (config/sensors/*.toml)."""
    path = Path(path)
    return parse_sensor_profile(read_toml(path), str(path))


SHIPPED_PROFILES = Path(__file__).resolve().parents[2] / "config" / "sensors"


def profile_names() -> list[str]:
    """The profiles that ship in config/sensors/."""
    return sorted(p.stem for p in SHIPPED_PROFILES.glob("*.toml"))


def resolve_sensor_profile(name: str, base: Path | None = None) -> SensorProfile:
    """A profile by name (config/sensors/NAME.toml) or by file path (relative to `base`,
    e.g. the scenario's folder)."""
    if name.endswith(".toml") or "/" in name:
        path = Path(name) if base is None else base / name
    else:
        path = SHIPPED_PROFILES / f"{name}.toml"
        if not path.is_file():
            raise ConfigError(f"sensor profile {name!r}: not one of "
                              f"{', '.join(profile_names())} (or a .toml file)")
    if not path.is_file():
        raise ConfigError(f"sensor profile {name!r}: no such file {path}")
    return load_sensor_profile(path)
