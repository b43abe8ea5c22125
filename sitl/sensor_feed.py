"""What the simulator's sensors send in one control period (a model sensor profile).

Pure and I/O-free: given the plant states at the physics steps of a period, in time order,
`SensorFeed.period` returns the simulator link's messages for them, as a real vehicle gets
them (DESIGN.md section 3): one HIL_SENSOR per IMU sample (FRD specific force and rate, with
the magnetometer and barometer fields flagged when they are new) and each motion-capture
pose as ODOMETRY (estimator_type MOCAP, stamped with its capture time, its covariance)
once its latency has passed, placed before the IMU sample of the same instant. The
process (`sitl/node.py`) and the in-process runner share it, so both send the same samples.
"""

from __future__ import annotations

from collections.abc import Sequence

from common.config import ConfigError
from common.frames import enu_to_ned, flu_to_frd, q_enu_flu_to_ned_frd
from common.mavlink import MAV
from common.sensors_config import SensorProfile
from common.simlink import HilSensor, Odometry, pose_covariance
from sitl.plant import Plant, PlantState
from sitl.sensors import SensorSuite

SEA_LEVEL_HPA = 1013.25
TEMPERATURE_C = 15.0
IMU_FIELDS = 0x3F  # HIL_SENSOR_UPDATED_{X,Y,Z}ACC | {X,Y,Z}GYRO
MAG_FIELDS = 0x1C0  # HIL_SENSOR_UPDATED_{X,Y,Z}MAG
BARO_FIELDS = 0x200 | 0x800 | 0x1000  # ABS_PRESSURE | PRESSURE_ALT | TEMPERATURE
_NAN3 = (float("nan"),) * 3


def pressure_hpa(alt_amsl_m: float) -> float:
    """ISA pressure at an altitude (the barometric formula below 11 km)."""
    return SEA_LEVEL_HPA * (1.0 - 2.25577e-5 * alt_amsl_m) ** 5.25588


def _period_us(rate_hz: float, physics_dt_us: int, what: str) -> int:
    period = round(1e6 / rate_hz)
    if period % physics_dt_us:
        raise ConfigError(f"sensor profile: {what} period {period} us is not a multiple of "
                          f"the physics step {physics_dt_us} us")
    return period


class SensorFeed:
    """The seeded sensor models of a profile, sampled on the plant's physics steps."""

    def __init__(self, profile: SensorProfile, seed: int, plant: Plant, control_dt_us: int,
                 home_alt_m: float = 0.0) -> None:
        dt = plant.dt_us
        self.imu_us = _period_us(profile.imu.rate_hz, dt, "IMU")
        if control_dt_us % self.imu_us:
            raise ConfigError(f"sensor profile {profile.name!r}: IMU period {self.imu_us} us "
                              f"does not divide the control period {control_dt_us} us")
        self.baro_us = _period_us(profile.baro.rate_hz, dt, "barometer")
        self.mag_us = _period_us(profile.mag.rate_hz, dt, "magnetometer")
        self.mocap_us = _period_us(profile.mocap.rate_hz, dt, "motion capture")
        self.profile = profile
        self.plant = plant
        self.suite = SensorSuite.from_profile(profile, seed)
        self.home_alt_m = home_alt_m
        cfg = profile.mocap
        self.mocap_cov = pose_covariance(max(cfg.position_noise_m, 1e-6) ** 2,
                                         max(cfg.attitude_noise_rad, 1e-6) ** 2)
        self._last_us = -1

    def period(self, states: Sequence[PlantState]) -> list[HilSensor | Odometry]:
        """The messages for these physics-step states (times increasing, each once)."""
        out: list[HilSensor | Odometry] = []
        suite = self.suite
        for s in states:
            t = s.time_us
            if t <= self._last_us:
                raise ValueError(f"sensor feed: time {t} us after {self._last_us} us")
            self._last_us = t
            t_s = t * 1e-6
            if t % self.mocap_us == 0:
                suite.mocap.capture(t_s, s.p_enu_m, s.q_enu_flu)
            for pose in suite.mocap.deliver((t + 0.5) * 1e-6):
                out.append(Odometry(round(pose.capture_s * 1e6), enu_to_ned(pose.p_enu_m),
                                    q_enu_flu_to_ned_frd(pose.q_enu_flu), _NAN3, _NAN3,
                                    MAV.MAV_ESTIMATOR_TYPE_MOCAP, self.mocap_cov))
            if t % self.imu_us:
                continue
            imu = suite.imu.sample(t_s, self.imu_us * 1e-6, s.omega_flu_rad_s,
                                   self.plant.specific_force_flu(s))
            fields = IMU_FIELDS
            mag = _NAN3
            if t % self.mag_us == 0:
                mag = flu_to_frd(suite.mag.sample(t_s, s.q_enu_flu).b_flu_gauss)
                fields |= MAG_FIELDS
            pressure = alt = float("nan")
            if t % self.baro_us == 0:
                alt = self.home_alt_m + suite.baro.sample(t_s, s.p_enu_m).alt_m
                pressure = pressure_hpa(alt)
                fields |= BARO_FIELDS
            out.append(HilSensor(t, flu_to_frd(imu.f_flu_m_s2), flu_to_frd(imu.omega_flu_rad_s),
                                 mag, pressure, alt, TEMPERATURE_C, fields))
        return out
