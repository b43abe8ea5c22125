"""What the simulator's sensors send in one control period (a model sensor profile).

Pure and I/O-free: given the plant states at the physics steps of a period, in time order,
`SensorFeed.period` returns the simulator link's messages for them, as a real vehicle gets
them (DESIGN.md section 3): one HIL_SENSOR per IMU sample (FRD specific force and rate, with
the magnetometer and barometer fields flagged when they are new) and each motion-capture
pose as ODOMETRY (estimator_type MOCAP, stamped with its capture time, its covariance)
once its latency has passed, placed before the IMU sample of the same instant. The
process (`sitl/node.py`) and the in-process runner share it, so both send the same samples.

Injected faults (the scenario's [[sensor_fault]], `start_flight`) act on what the models
return, never on their draws: every sensor draws as without the fault and the fault then
overrides the value, so a run with a fault is the run without it up to the fault.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

from common.config import SENSOR_FAULT_KINDS, ConfigError, SensorFault
from common.frames import enu_to_ned, flu_to_frd, q_enu_flu_to_ned_frd
from common.mavlink import MAV
from common.quaternion import Vec3
from common.sensors_config import SensorProfile
from common.simlink import HilSensor, Odometry, pose_covariance
from sitl.plant import Plant, PlantState
from sitl.sensors import ImuSample, SensorSuite

SEA_LEVEL_HPA = 1013.25
TEMPERATURE_C = 15.0
IMU_FIELDS = 0x3F  # HIL_SENSOR_UPDATED_{X,Y,Z}ACC | {X,Y,Z}GYRO
MAG_FIELDS = 0x1C0  # HIL_SENSOR_UPDATED_{X,Y,Z}MAG
BARO_FIELDS = 0x200 | 0x800 | 0x1000  # ABS_PRESSURE | PRESSURE_ALT | TEMPERATURE
_NAN3 = (float("nan"),) * 3
_NAN4 = (float("nan"),) * 4


def pressure_hpa(alt_amsl_m: float) -> float:
    """ISA pressure at an altitude (the barometric formula below 11 km)."""
    return SEA_LEVEL_HPA * float((1.0 - 2.25577e-5 * alt_amsl_m) ** 5.25588)


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
        self.flight_start_us: int | None = None
        # The faults as windows on the simulation clock [start_us, end_us) (end None: open).
        self._faults: list[tuple[str, int, int | None, Vec3]] = []

    def start_flight(self, t0_us: int, faults: Sequence[SensorFault] = ()) -> None:
        """The flight starts at t0_us (simulation clock): the faults' times count from it."""
        if self.flight_start_us is not None:
            raise ValueError(f"sensor feed: the flight started at {self.flight_start_us} us "
                             f"already")
        windows = []
        for f in faults:
            if f.kind not in SENSOR_FAULT_KINDS:
                raise ConfigError(f"sensor fault: kind {f.kind!r} is not one of "
                                  f"{', '.join(SENSOR_FAULT_KINDS)}")
            if not (math.isfinite(f.start_s) and f.start_s >= 0.0 and f.end_s > f.start_s):
                raise ConfigError(f"sensor fault {f.kind}: expected 0 <= start_s < end_s, "
                                  f"got [{f.start_s}, {f.end_s})")
            if len(f.amplitude) != 3 or not all(math.isfinite(a) for a in f.amplitude):
                raise ConfigError(f"sensor fault {f.kind}: amplitude: expected 3 finite "
                                  f"numbers, got {f.amplitude!r}")
            end = t0_us + round(f.end_s * 1e6) if math.isfinite(f.end_s) else None
            windows.append((f.kind, t0_us + round(f.start_s * 1e6), end, f.amplitude))
        self.flight_start_us = t0_us
        self._faults = windows

    def _active(self, kind: str, t_us: int) -> list[Vec3]:
        """The amplitudes of the faults of this kind active at t_us."""
        return [a for k, start, end, a in self._faults
                if k == kind and start <= t_us and (end is None or t_us < end)]

    def _imu_faults(self, t_us: int, imu: ImuSample) -> ImuSample:
        if self._active("imu_nan", t_us):
            return ImuSample(imu.t_s, _NAN3, _NAN3)
        steps = self._active("gyro_bias_step", t_us)
        if not steps:
            return imu
        limit = self.profile.imu.gyro.range_rad_s
        w = [imu.omega_flu_rad_s[i] + sum(a[i] for a in steps) for i in range(3)]
        w = [min(max(c, -limit), limit) for c in w]
        return ImuSample(imu.t_s, (w[0], w[1], w[2]), imu.f_flu_m_s2)

    def _capture(self, t_us: int, s: PlantState) -> None:
        """One motion-capture frame (always drawn), then the faults of its capture time."""
        mocap = self.suite.mocap
        queued = len(mocap.queue)
        mocap.capture(t_us * 1e-6, s.p_enu_m, s.q_enu_flu)
        if len(mocap.queue) == queued or not self._faults:
            return  # dropped by the model, or no fault to apply
        if self._active("mocap_off", t_us):
            mocap.queue.pop()
        elif self._active("pose_nan", t_us):
            mocap.queue[-1] = dataclasses.replace(mocap.queue[-1], p_enu_m=_NAN3,
                                                  q_enu_flu=_NAN4)

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
                self._capture(t, s)
            for pose in suite.mocap.deliver((t + 0.5) * 1e-6):
                out.append(Odometry(round(pose.capture_s * 1e6), enu_to_ned(pose.p_enu_m),
                                    q_enu_flu_to_ned_frd(pose.q_enu_flu), _NAN3, _NAN3,
                                    MAV.MAV_ESTIMATOR_TYPE_MOCAP, self.mocap_cov))
            if t % self.imu_us:
                continue
            imu = suite.imu.sample(t_s, self.imu_us * 1e-6, s.omega_flu_rad_s,
                                   self.plant.specific_force_flu(s))
            if self._faults:
                imu = self._imu_faults(t, imu)
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
