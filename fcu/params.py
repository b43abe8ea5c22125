"""The FCU's parameters (PARAM_* protocol): gains of eq. (3)/(16) and mission settings.

One table with name (at most 16 characters, as MAVLink carries them), default, range, unit
and description, as PX4's *_params.yaml. Values are float32 (MAV_PARAM_TYPE_REAL32). A set
that leaves the range, or a gain set that violates the Routh-Hurwitz condition, is refused
and the old value stays.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

from common.config import ConfigError, Gains, VehicleConfig, check_stability
from fcu.commander import FlightSettings
from fcu.estimator.settings import EstimatorSettings
from fcu.failsafe import FailsafeSettings
from fcu.manual import StickSettings
from fcu.mission.limits import MissionLimits
from fcu.pipeline import Pipeline

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


def _f32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", x))[0]


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


SPECS: tuple[ParamSpec, ...] = (
    *_gain_specs(),
    ParamSpec("DQ_DAMPING", 0.0, 0.0, 1.0, "enum",
              "damping D of eq. (16): 0 = 2 k_d.(ln q_e)', 1 = k_d.xi_e (eq. 33)"),
    ParamSpec("CA_LAG_COMP", 1.0, 0.0, 1.0, "enum",
              "allocation: 1 = lead rotor speeds and tilts for the rotor lag (tau up/down) and "
              "the tilt rate limit, from the reference; 0 = plain eqs. (28-29)"),
    ParamSpec("MIS_TKO_SPD", 1.0, 0.05, 10.0, "m/s", "takeoff climb speed when p2 is 0"),
    ParamSpec("MIS_CRUISE_SPD", 2.0, 0.05, 20.0, "m/s", "waypoint travel speed"),
    ParamSpec("MIS_LAND_SPD", 0.5, 0.05, 5.0, "m/s", "landing descent speed"),
    ParamSpec("MIS_ENV_CHK", 1.0, 0.0, 1.0, "enum",
              "mission envelope check: 1 = stretch speed-timed legs and refuse timed items "
              "the rotors cannot fly, 0 = off (accept any profile)"),
    ParamSpec("GF_MAX_DIST", 1000.0, 1.0, 100000.0, "m",
              "geofence: farthest mission point from the origin"),
    ParamSpec("COM_OF_LOSS_T", 1.0, 0.1, 60.0, "s", "offboard setpoint loss timeout (to HOLD)"),
    ParamSpec("COM_DL_LOSS_T", 0.0, 0.0, 300.0, "s",
              "GCS heartbeat loss: HOLD after this long without one (0: off)"),
    ParamSpec("COM_DL_LAND_T", 0.0, 0.0, 600.0, "s",
              "after GCS loss: LAND after this long in HOLD (0: never)"),
    ParamSpec("COM_STATE_LOSS_T", 1.0, 0.05, 60.0, "s",
              "state input loss: stop commanding motion and disarm after this long"),
    ParamSpec("COM_SAT_T", 2.0, 0.01, 60.0, "s",
              "rotor speed saturation for longer than this is reported"),
    ParamSpec("COM_SAT_ACT", 0.0, 0.0, 1.0, "enum",
              "on long saturation: 0 = report, 1 = abort the mission to HOLD"),
    ParamSpec("COM_ACT_RATE_T", 0.1, 0.002, 60.0, "s",
              "a tilt servo commanded faster than its rate limit (by a model of it) or a rotor "
              "clamped at its speed limit for longer than this is reported"),
    ParamSpec("COM_DIV_POS", 10.0, 0.1, 1000.0, "m",
              "divergence: tracking error beyond this disarms"),
    ParamSpec("MIS_TAKEOFF_ALT", 2.5, 0.1, 100.0, "m",
              "TAKEOFF (MAV_CMD_NAV_TAKEOFF without altitude) climbs this much, then holds"),
    ParamSpec("RTL_RETURN_ALT", 10.0, 0.0, 150.0, "m",
              "RTL climbs to this height above home if lower, flies home, lands"),
    ParamSpec("MPC_XY_CRUISE", 5.0, 0.1, 20.0, "m/s", "RTL travel speed (distance / time)"),
    ParamSpec("COM_RC_LOSS_T", 0.5, 0.1, 35.0, "s",
              "POSCTL: MANUAL_CONTROL loss timeout (to HOLD)"),
    ParamSpec("MPC_VEL_MANUAL", 5.0, 0.1, 20.0, "m/s",
              "POSCTL: horizontal speed at full stick; OFFBOARD: approach speed"),
    ParamSpec("MPC_Z_VEL_MAX_UP", 3.0, 0.1, 8.0, "m/s",
              "POSCTL: climb speed at full stick; OFFBOARD: approach climb speed"),
    ParamSpec("MPC_Z_VEL_MAX_DN", 1.5, 0.1, 4.0, "m/s",
              "POSCTL: descent speed at full stick; OFFBOARD: approach descent speed"),
    ParamSpec("MPC_ACC_HOR", 3.0, 0.5, 15.0, "m/s^2",
              "POSCTL, OFFBOARD: horizontal acceleration limit"),
    ParamSpec("MPC_ACC_UP_MAX", 3.0, 0.5, 15.0, "m/s^2",
              "POSCTL, OFFBOARD: upward acceleration limit"),
    ParamSpec("MPC_ACC_DOWN_MAX", 3.0, 0.5, 15.0, "m/s^2",
              "POSCTL, OFFBOARD: downward acceleration limit"),
    ParamSpec("MPC_MAN_Y_MAX", 90.0, 0.0, 400.0, "deg/s", "POSCTL: yaw rate at full stick"),
    ParamSpec("MPC_JERK_MAX", 8.0, 0.5, 500.0, "m/s^3",
              "POSCTL: jerk limit (lower where the tilt servos need it)"),
    # The estimator (fcu/estimator/); EKF2's names and defaults where EKF2 has the figure.
    ParamSpec("EKF_EN", 0.0, 0.0, 1.0, "enum",
              "state source: 0 = ODOMETRY as the exact state, 1 = the estimator from "
              "HIL_SENSOR and the external pose (ODOMETRY, motion capture)"),
    ParamSpec("EKF_EV_DELAY", 0.02, 0.0, 0.3, "s",
              "fusion horizon behind the newest IMU sample (EKF2_EV_DELAY)"),
    ParamSpec("EKF_GYR_NOISE", 0.015, 1e-4, 1.0, "rad/s", "gyro noise (EKF2_GYR_NOISE)"),
    ParamSpec("EKF_ACC_NOISE", 0.35, 1e-3, 10.0, "m/s^2",
              "accelerometer noise (EKF2_ACC_NOISE)"),
    ParamSpec("EKF_GYR_B_NOISE", 1e-3, 0.0, 1.0, "rad/s^2",
              "gyro bias process noise (EKF2_GYR_B_NOISE)"),
    ParamSpec("EKF_ACC_B_NOISE", 2e-2, 0.0, 1.0, "m/s^3",
              "accelerometer bias process noise (ArduPilot EKF3's 2e-2: EKF2's 3e-3 "
              "under-models a bias walking 6e-3 m/s^3/sqrt(Hz), and the velocity lags)"),
    ParamSpec("EKF_EVP_NOISE", 0.001, 1e-5, 10.0, "m",
              "least external position noise, when the pose's covariance says less"),
    ParamSpec("EKF_EVA_NOISE", 0.002, 1e-5, 1.0, "rad",
              "least external attitude noise, when the pose's covariance says less"),
    ParamSpec("EKF_EV_GATE", 5.0, 1.0, 100.0, "SD",
              "innovation gate of the external pose (EKF2_EV_POS_GATE)"),
    ParamSpec("EKF_GATE_N", 20.0, 1.0, 10000.0, "count",
              "poses refused by the gate in a row: estimator inconsistent, LAND"),
    ParamSpec("IMU_GYRO_CUTOFF", 40.0, 0.0, 1000.0, "Hz",
              "with the estimator: low-pass cut-off of the rate the controller damps with "
              "(second-order Butterworth; 0: none), as PX4's IMU_GYRO_CUTOFF"),
    ParamSpec("COM_POS_LOSS_T", 1.0, 0.0, 60.0, "s",
              "pose source lost: dead-reckon this long, then HOLD"),
    ParamSpec("COM_POS_LAND_T", 2.0, 0.0, 600.0, "s",
              "pose source lost: LAND after this long in HOLD"),
)
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
            self.values[spec.name] = _f32(spec.default)
        self._load_gains(gains)

    def _load_gains(self, gains: Gains) -> None:
        for spec in SPECS:
            if spec.name.startswith("DQ_K"):
                key = spec.name[3:5].lower() + "_" + spec.name[5].lower()
                self.values[spec.name] = _f32(getattr(gains, key)["XYZ".index(spec.name[-1])])
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
        if armed and name in LOCKED_WHEN_ARMED and _f32(value) != self.values[name]:
            raise ParamError(f"{name} refused: the estimator's settings change only disarmed")
        if not math.isfinite(value) or not spec.lo <= value <= spec.hi:
            raise ParamError(f"{name} refused: {value:g} not in [{spec.lo:g}, {spec.hi:g}]")
        if spec.unit == "enum" and value != round(value):
            raise ParamError(f"{name} refused: must be an integer in [{spec.lo:g}, {spec.hi:g}]")
        trial = dict(self.values)
        trial[name] = _f32(value)
        if name.startswith("DQ_K"):
            try:
                check_stability(self.gains(trial))
            except ConfigError as exc:
                condition = str(exc).split("violates ", 1)[-1].split(" (", 1)[0]
                raise ParamError(f"{name} refused: violates {condition}") from None
        self.values = trial
        return trial[name]


def failsafe_settings(values: dict[str, float]) -> FailsafeSettings:
    """The COM_* parameters as the failsafe stage's settings."""
    return FailsafeSettings(
        gcs_loss_s=values["COM_DL_LOSS_T"], gcs_loss_land_s=values["COM_DL_LAND_T"],
        state_loss_s=values["COM_STATE_LOSS_T"], saturation_s=values["COM_SAT_T"],
        saturation_hold=values["COM_SAT_ACT"] == 1.0,
        actuator_limit_s=values["COM_ACT_RATE_T"], divergence_m=values["COM_DIV_POS"],
        pose_loss_s=values["COM_POS_LOSS_T"], pose_loss_land_s=values["COM_POS_LAND_T"],
        gate_failures=round(values["EKF_GATE_N"]))


def estimator_settings(values: dict[str, float], gravity_m_s2: float
                       ) -> EstimatorSettings | None:
    """The EKF_* parameters as the estimator's settings; None when EKF_EN is 0."""
    if values["EKF_EN"] != 1.0:
        return None
    return EstimatorSettings(
        gravity_m_s2=gravity_m_s2, gyro_noise_rad_s=values["EKF_GYR_NOISE"],
        accel_noise_m_s2=values["EKF_ACC_NOISE"],
        gyro_bias_noise_rad_s2=values["EKF_GYR_B_NOISE"],
        accel_bias_noise_m_s3=values["EKF_ACC_B_NOISE"],
        pose_pos_noise_m=values["EKF_EVP_NOISE"], pose_att_noise_rad=values["EKF_EVA_NOISE"],
        pose_delay_s=values["EKF_EV_DELAY"], pose_gate_sd=values["EKF_EV_GATE"])


def mission_limits(values: dict[str, float], vehicle: VehicleConfig | None = None
                   ) -> MissionLimits:
    """The MIS_* and GF_* parameters as the mission's limits."""
    return MissionLimits(max_distance_m=values["GF_MAX_DIST"],
                         cruise_speed_m_s=values["MIS_CRUISE_SPD"],
                         land_speed_m_s=values["MIS_LAND_SPD"],
                         takeoff_speed_m_s=values["MIS_TKO_SPD"],
                         vehicle=vehicle if values["MIS_ENV_CHK"] == 1.0 else None)


def flight_settings(values: dict[str, float]) -> FlightSettings:
    """The automatic modes' (MIS_TAKEOFF_ALT, RTL_*, MPC_XY_CRUISE) and POSCTL's (MPC_*,
    COM_RC_LOSS_T) parameters."""
    sticks = StickSettings(
        speed_xy_m_s=values["MPC_VEL_MANUAL"], speed_up_m_s=values["MPC_Z_VEL_MAX_UP"],
        speed_down_m_s=values["MPC_Z_VEL_MAX_DN"], acc_xy_m_s2=values["MPC_ACC_HOR"],
        acc_up_m_s2=values["MPC_ACC_UP_MAX"], acc_down_m_s2=values["MPC_ACC_DOWN_MAX"],
        yaw_rate_deg_s=values["MPC_MAN_Y_MAX"], jerk_m_s3=values["MPC_JERK_MAX"])
    return FlightSettings(takeoff_alt_m=values["MIS_TAKEOFF_ALT"],
                          rtl_return_alt_m=values["RTL_RETURN_ALT"],
                          rtl_cruise_m_s=values["MPC_XY_CRUISE"],
                          manual_timeout_s=values["COM_RC_LOSS_T"], sticks=sticks)


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
