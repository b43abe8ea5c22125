"""The FCU's parameters (PARAM_* protocol): gains of eq. (3)/(16) and mission settings.

One table with name (at most 16 characters, as MAVLink carries them), default, range, unit
and description, as PX4's *_params.yaml. Values are float32 (MAV_PARAM_TYPE_REAL32). A set
that leaves the range, or a gain set that violates the Routh-Hurwitz condition, is refused
and the old value stays.

A parameter that sets a field of a settings dataclass (`FlightSettings`, `StickSettings`,
`FailsafeSettings`, `EstimatorSettings`, `MissionLimits`, `Gains`) names it (`field`) and
takes its default from the dataclass, so the two cannot disagree; the converters
(`failsafe_settings`, ...) build each dataclass from its fields' parameters. The one
deliberate difference is in `DEFAULT_OVERRIDES`, with its reason. docs/parameters.md is
generated from this table (`fcu.edge.params_doc`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeVar

from common.config.scenario import ConfigError, Gains, VehicleConfig, check_stability
from common.wire.rounding import f32
from fcu.estimator.settings import EstimatorSettings
from fcu.mission.limits import MissionLimits
from fcu.modes.manual import StickSettings
from fcu.modes.settings import FlightSettings
from fcu.pipeline import Pipeline
from fcu.safety.failsafe import FailsafeSettings

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

AXES = "XYZ"
DAMPING_CODES = ("log_rate", "twist")


@dataclass(frozen=True)
class ParamSpec:
    name: str
    default: float
    lo: float
    hi: float
    unit: str
    description: str
    field: str = ""  # "Class.field" of the settings dataclass it sets, "" for none


_SETTINGS: dict[str, type[Any]] = {cls.__name__: cls for cls in (
    FlightSettings, StickSettings, FailsafeSettings, EstimatorSettings, MissionLimits, Gains)}
# Table defaults that differ from their dataclass's on purpose: name -> (default, reason).
DEFAULT_OVERRIDES: dict[str, tuple[float, str]] = {
    "EKF_ACC_B_NOISE": (2e-2, "EstimatorSettings keeps EKF2's 3e-3, on which the "
                              "estimator's own tests are tuned"),
}


def field_default(path: str) -> float:
    """The default of the dataclass field "Class.field" as a parameter value: a bool as 0 or
    1, Gains.damping as its index in DAMPING_CODES."""
    cls_name, name = path.split(".")
    value: object = next(f.default for f in dataclasses.fields(_SETTINGS[cls_name])
                         if f.name == name)
    if path == "Gains.damping":
        return float(DAMPING_CODES.index(str(value)))
    if not isinstance(value, (int, float)):
        raise TypeError(f"{path} has no numeric default")
    return float(value)


def _bound(name: str, path: str, lo: float, hi: float, unit: str,
           description: str) -> ParamSpec:
    """A parameter that sets the dataclass field `path`, its default read from there (or from
    DEFAULT_OVERRIDES)."""
    default = DEFAULT_OVERRIDES[name][0] if name in DEFAULT_OVERRIDES else field_default(path)
    return ParamSpec(name, default, lo, hi, unit, description, path)


def _gain_specs() -> list[ParamSpec]:
    specs = []
    for key, label in (("kp", "proportional"), ("ki", "integral"), ("kd", "derivative")):
        for part, what in (("r", "attitude (real part)"), ("d", "position (dual part)")):
            for i, axis in enumerate(AXES):
                lo = 0.0
                specs.append(ParamSpec(f"DQ_{key.upper()}{part.upper()}_{axis}", math.nan, lo,
                                       1000.0, "1/s^n",
                                       f"{label} gain, {what}, axis {i + 1} (eq. 3)"))
    return specs


# The table in groups (headings of docs/parameters.md); the order is the wire's param_index.
GROUPS: tuple[tuple[str, tuple[ParamSpec, ...]], ...] = (("Controller", (
    *_gain_specs(),
    _bound("DQ_DAMPING", "Gains.damping", 0.0, 1.0, "enum",
           "damping D of eq. (16): 0 = 2 k_d.(ln q_e)', 1 = k_d.xi_e (eq. 33)"),
)), ("Allocation", (
    ParamSpec("CA_LAG_COMP", 1.0, 0.0, 1.0, "enum",
              "allocation: 1 = lead rotor speeds and tilts for the rotor lag (tau up/down) and "
              "the tilt rate limit, from the reference; 0 = plain eqs. (28-29)"),
)), ("Missions", (
    _bound("MIS_TKO_SPD", "MissionLimits.takeoff_speed_m_s", 0.05, 10.0, "m/s",
           "takeoff climb top speed when p2 is 0"),
    _bound("MIS_CRUISE_SPD", "MissionLimits.cruise_speed_m_s", 0.05, 20.0, "m/s",
           "waypoint travel top speed (a leg lasts 1.875 distance / speed)"),
    _bound("MIS_LAND_SPD", "MissionLimits.land_speed_m_s", 0.05, 5.0, "m/s",
           "landing descent top speed"),
    _bound("MIS_ITEM_MAX_S", "MissionLimits.item_max_s", 1.0, 86400.0, "s",
           "longest item duration a refusal proposes: an item the envelope check would need "
           "to lengthen beyond it is refused as not flyable"),
    ParamSpec("MIS_ENV_CHK", 1.0, 0.0, 1.0, "enum",
              "mission envelope check: 1 = stretch speed-timed legs and refuse timed items "
              "the rotors cannot fly, 0 = off (accept any profile)"),
    _bound("GF_MAX_DIST", "MissionLimits.max_distance_m", 1.0, 100000.0, "m",
           "geofence: farthest mission point from the origin"),
)), ("Failsafes", (
    ParamSpec("COM_OF_LOSS_T", 1.0, 0.1, 60.0, "s", "offboard setpoint loss timeout (to HOLD)"),
    _bound("COM_DL_LOSS_T", "FailsafeSettings.gcs_loss_s", 0.0, 300.0, "s",
           "GCS heartbeat loss: HOLD after this long without one (0: off)"),
    _bound("COM_DL_LAND_T", "FailsafeSettings.gcs_loss_land_s", 0.0, 600.0, "s",
           "after GCS loss: LAND after this long in HOLD (0: never)"),
    _bound("COM_STATE_LOSS_T", "FailsafeSettings.state_loss_s", 0.05, 60.0, "s",
           "state input loss: stop commanding motion and disarm after this long"),
    _bound("COM_SAT_T", "FailsafeSettings.saturation_s", 0.01, 60.0, "s",
           "rotor speed saturation for longer than this is reported"),
    _bound("COM_SAT_ACT", "FailsafeSettings.saturation_hold", 0.0, 1.0, "enum",
           "on long saturation: 0 = report, 1 = abort the mission to HOLD"),
    _bound("COM_ACT_RATE_T", "FailsafeSettings.actuator_limit_s", 0.002, 60.0, "s",
           "a tilt servo commanded faster than its rate limit (by a model of it) or a rotor "
           "clamped at its speed limit for longer than this is reported"),
    _bound("COM_DIV_POS", "FailsafeSettings.divergence_m", 0.1, 1000.0, "m",
           "divergence: tracking error beyond this disarms"),
)), ("Automatic modes", (
    _bound("MIS_TAKEOFF_ALT", "FlightSettings.takeoff_alt_m", 0.1, 100.0, "m",
           "TAKEOFF (MAV_CMD_NAV_TAKEOFF without altitude) climbs this much, then holds"),
    _bound("RTL_RETURN_ALT", "FlightSettings.rtl_return_alt_m", 0.0, 150.0, "m",
           "RTL climbs to this height above home if lower, flies home, lands"),
    _bound("MPC_XY_CRUISE", "FlightSettings.rtl_cruise_m_s", 0.1, 20.0, "m/s",
           "RTL travel top speed"),
)), ("POSCTL and OFFBOARD", (
    _bound("COM_RC_LOSS_T", "FlightSettings.manual_timeout_s", 0.1, 35.0, "s",
           "POSCTL: MANUAL_CONTROL loss timeout (to HOLD)"),
    _bound("MPC_VEL_MANUAL", "StickSettings.speed_xy_m_s", 0.1, 20.0, "m/s",
           "POSCTL: horizontal speed at full stick; OFFBOARD: approach speed"),
    _bound("MPC_Z_VEL_MAX_UP", "StickSettings.speed_up_m_s", 0.1, 8.0, "m/s",
           "POSCTL: climb speed at full stick; OFFBOARD: approach climb speed"),
    _bound("MPC_Z_VEL_MAX_DN", "StickSettings.speed_down_m_s", 0.1, 4.0, "m/s",
           "POSCTL: descent speed at full stick; OFFBOARD: approach descent speed"),
    _bound("MPC_ACC_HOR", "StickSettings.acc_xy_m_s2", 0.5, 15.0, "m/s^2",
           "POSCTL, OFFBOARD: horizontal acceleration limit"),
    _bound("MPC_ACC_UP_MAX", "StickSettings.acc_up_m_s2", 0.5, 15.0, "m/s^2",
           "POSCTL, OFFBOARD: upward acceleration limit"),
    _bound("MPC_ACC_DOWN_MAX", "StickSettings.acc_down_m_s2", 0.5, 15.0, "m/s^2",
           "POSCTL, OFFBOARD: downward acceleration limit"),
    _bound("MPC_MAN_Y_MAX", "StickSettings.yaw_rate_deg_s", 0.0, 400.0, "deg/s",
           "POSCTL: yaw rate at full stick"),
    _bound("MPC_JERK_MAX", "StickSettings.jerk_m_s3", 0.5, 500.0, "m/s^3",
           "POSCTL: jerk limit (lower where the tilt servos need it)"),
)), ("Estimator", (
    # fcu/estimator/; EKF2's names and defaults where EKF2 has the figure.
    ParamSpec("EKF_EN", 0.0, 0.0, 1.0, "enum",
              "state source: 0 = ODOMETRY as the exact state, 1 = the estimator from "
              "HIL_SENSOR and the external pose (ODOMETRY, motion capture)"),
    _bound("EKF_EV_DELAY", "EstimatorSettings.pose_delay_s", 0.0, 0.3, "s",
           "fusion horizon behind the newest IMU sample (EKF2_EV_DELAY)"),
    _bound("EKF_GYR_NOISE", "EstimatorSettings.gyro_noise_rad_s", 1e-4, 1.0, "rad/s",
           "gyro noise (EKF2_GYR_NOISE)"),
    _bound("EKF_ACC_NOISE", "EstimatorSettings.accel_noise_m_s2", 1e-3, 10.0, "m/s^2",
           "accelerometer noise (EKF2_ACC_NOISE)"),
    _bound("EKF_GYR_B_NOISE", "EstimatorSettings.gyro_bias_noise_rad_s2", 0.0, 1.0, "rad/s^2",
           "gyro bias process noise (EKF2_GYR_B_NOISE)"),
    _bound("EKF_ACC_B_NOISE", "EstimatorSettings.accel_bias_noise_m_s3", 0.0, 1.0, "m/s^3",
           "accelerometer bias process noise (ArduPilot EKF3's 2e-2: EKF2's 3e-3 "
           "under-models a bias walking 6e-3 m/s^3/sqrt(Hz), and the velocity lags)"),
    _bound("EKF_EVP_NOISE", "EstimatorSettings.pose_pos_noise_m", 1e-5, 10.0, "m",
           "least external position noise, when the pose's covariance says less"),
    _bound("EKF_EVA_NOISE", "EstimatorSettings.pose_att_noise_rad", 1e-5, 1.0, "rad",
           "least external attitude noise, when the pose's covariance says less"),
    _bound("EKF_EV_GATE", "EstimatorSettings.pose_gate_sd", 1.0, 100.0, "SD",
           "innovation gate of the external pose (EKF2_EV_POS_GATE)"),
    _bound("EKF_GATE_N", "FailsafeSettings.gate_failures", 1.0, 10000.0, "count",
           "poses refused by the gate in a row: estimator inconsistent, LAND"),
    ParamSpec("IMU_GYRO_CUTOFF", 40.0, 0.0, 1000.0, "Hz",
              "with the estimator: low-pass cut-off of the rate the controller damps with "
              "(second-order Butterworth; 0: none), as PX4's IMU_GYRO_CUTOFF"),
    _bound("COM_POS_LOSS_T", "FailsafeSettings.pose_loss_s", 0.0, 60.0, "s",
           "pose source lost: dead-reckon this long, then HOLD"),
    _bound("COM_POS_LAND_T", "FailsafeSettings.pose_loss_land_s", 0.0, 600.0, "s",
           "pose source lost: LAND after this long in HOLD"),
)))
SPECS: tuple[ParamSpec, ...] = tuple(s for _, group in GROUPS for s in group)
# Parameters that change the state source: refused while armed (PX4 asks for a reboot).
LOCKED_WHEN_ARMED = frozenset(s.name for s in SPECS
                              if s.name.startswith("EKF_") or s.name == "IMU_GYRO_CUTOFF")
BY_NAME = {s.name: s for s in SPECS}


class ParamError(ValueError):
    """A parameter set that was refused (unknown name, out of range, unstable gains)."""


class ParamStore:
    """Parameter values, initialised from the gains of the configuration."""

    def __init__(self, gains: Gains) -> None:
        self.values: dict[str, float] = {}
        for spec in SPECS:
            self.values[spec.name] = f32(spec.default)
        self._load_gains(gains)

    def _load_gains(self, gains: Gains) -> None:
        for spec in SPECS:
            if spec.name.startswith("DQ_K"):
                key = spec.name[3:5].lower() + "_" + spec.name[5].lower()
                self.values[spec.name] = f32(getattr(gains, key)["XYZ".index(spec.name[-1])])
        self.values["DQ_DAMPING"] = float(DAMPING_CODES.index(gains.damping))

    @property
    def names(self) -> list[str]:
        return [s.name for s in SPECS]

    def index(self, name: str) -> int:
        return self.names.index(name)

    def gains(self, values: dict[str, float] | None = None) -> Gains:
        v = self.values if values is None else values
        def axes(key: str) -> tuple[float, float, float]:
            stem = f"DQ_{key[:2].upper()}{key[3].upper()}_"
            return (v[stem + "X"], v[stem + "Y"], v[stem + "Z"])

        return Gains(axes("kp_r"), axes("kp_d"), axes("ki_r"), axes("ki_d"), axes("kd_r"),
                     axes("kd_d"), damping=DAMPING_CODES[round(v["DQ_DAMPING"])])

    def set(self, name: str, value: float, armed: bool = False) -> float:
        """Set a parameter; returns the stored (float32) value or raises ParamError."""
        spec = BY_NAME.get(name)
        if spec is None:
            raise ParamError(f"unknown parameter {name}")
        if armed and name in LOCKED_WHEN_ARMED and f32(value) != self.values[name]:
            raise ParamError(f"{name} refused: the estimator's settings change only disarmed")
        if not math.isfinite(value) or not spec.lo <= value <= spec.hi:
            raise ParamError(f"{name} refused: {value:g} not in [{spec.lo:g}, {spec.hi:g}]")
        if spec.unit == "enum" and value != round(value):
            raise ParamError(f"{name} refused: must be an integer in [{spec.lo:g}, {spec.hi:g}]")
        trial = dict(self.values)
        trial[name] = f32(value)
        if name.startswith("DQ_K"):
            try:
                check_stability(self.gains(trial))
            except ConfigError as exc:
                condition = str(exc).split("violates ", 1)[-1].split(" (", 1)[0]
                raise ParamError(f"{name} refused: violates {condition}") from None
        self.values = trial
        return trial[name]


_T = TypeVar("_T", bound="DataclassInstance")


def _fields_of(cls: type[_T], values: dict[str, float], **given: Any) -> _T:
    """An instance of the settings dataclass `cls` with every field a parameter sets (`field`)
    taken from `values` (a bool field is value == 1, an int one rounded) and the rest from
    `given` or the dataclass's defaults."""
    defaults: dict[str, object] = {f.name: f.default for f in dataclasses.fields(cls)}
    prefix = cls.__name__ + "."
    for spec in SPECS:
        if spec.field.startswith(prefix):
            name = spec.field[len(prefix):]
            value = values[spec.name]
            default = defaults[name]
            given[name] = (value == 1.0 if isinstance(default, bool)
                           else round(value) if isinstance(default, int) else value)
    return cls(**given)


def failsafe_settings(values: dict[str, float]) -> FailsafeSettings:
    """The COM_* (and EKF_GATE_N) parameters as the failsafe stage's settings."""
    return _fields_of(FailsafeSettings, values)


def estimator_settings(values: dict[str, float], gravity_m_s2: float
                       ) -> EstimatorSettings | None:
    """The EKF_* parameters as the estimator's settings; None when EKF_EN is 0."""
    if values["EKF_EN"] != 1.0:
        return None
    return _fields_of(EstimatorSettings, values, gravity_m_s2=gravity_m_s2)


def mission_limits(values: dict[str, float], vehicle: VehicleConfig | None = None
                   ) -> MissionLimits:
    """The MIS_* and GF_* parameters as the mission's limits."""
    return _fields_of(MissionLimits, values,
                      vehicle=vehicle if values["MIS_ENV_CHK"] == 1.0 else None)


def flight_settings(values: dict[str, float]) -> FlightSettings:
    """The automatic modes' (MIS_TAKEOFF_ALT, RTL_*, MPC_XY_CRUISE) and POSCTL's (MPC_*,
    COM_RC_LOSS_T) parameters."""
    return _fields_of(FlightSettings, values, sticks=_fields_of(StickSettings, values))


def apply_params(store: ParamStore, pipeline: Pipeline) -> MissionLimits:
    """Put the parameters in force in the pipeline; returns the mission limits (the mission
    protocol checks uploads against them too)."""
    v = store.values
    limits = mission_limits(v, pipeline.vehicle)
    pipeline.configure(store.gains(), limits, failsafe_settings(v), v["COM_OF_LOSS_T"],
                       flight_settings(v))
    if not pipeline.armed:
        pipeline.set_gyro_cutoff(v["IMU_GYRO_CUTOFF"])
        pipeline.use_estimator(estimator_settings(v, pipeline.vehicle.gravity_m_s2))
    pipeline.core.set_lag_compensation(v["CA_LAG_COMP"] == 1.0)
    return limits
