"""What the simulator's sensors send in one control period (a model sensor profile).

Pure and I/O-free: given the plant states at the physics steps of a period, in time order,
`SensorFeed.period` returns the simulator link's messages for them, as a real vehicle gets
them (docs/simulator-link.md#sensors): one HIL_SENSOR per IMU sample (FRD specific force and
rate, with the magnetometer and barometer fields flagged when they are new) and each motion-capture
pose as ODOMETRY (estimator_type MOCAP, stamped with its capture time, its covariance)
once its latency has passed, placed before the IMU sample of the same instant. Each sensor
samples at its own rate and jitter, on or off the physics grid (`SampleClock`, `state_at`).
The process (`sitl/node.py`) and the in-process runner share it, so both send the same
samples.

The accelerometer reads the plant's specific force at the sample's instant plus the ground
contact's impulse (`Plant.specific_force_flu`): a touchdown's velocity change counts at the
end of its physics step, in the first IMU sample at or after it, spread over that sample's
interval, so that the samples integrate to the true velocity change whatever the IMU rate.
A profile's `imu.accel.contact_spread_s` > 0 spreads each touchdown's impulse evenly over
that long instead, from that sample on (the integral unchanged, the plant's dynamics
untouched): a landing gear's compliance stretches a real touchdown's deceleration over tens
of milliseconds, and a 0.7 m/s touchdown within one 4 ms sample (175 m/s^2) would clip at a
+-16 g accelerometer's range, losing part of the velocity change the estimator integrates.

Injected faults (the scenario's [[sensor_fault]], `start_flight`) act on what the models
return, never on their draws: every sensor draws as without the fault and the fault then
overrides the value, so a run with a fault is the run without it up to the fault.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from common.config.scenario import SENSOR_FAULT_KINDS, ConfigError, SensorFault
from common.config.sensors import IMU_RATE_MIN_HZ, SensorProfile, check_servable
from common.frames import enu_to_ned, flu_to_frd, q_enu_flu_to_ned_frd
from common.jit import compiled_for
from common.quaternion import Vec3, q_conj, q_exp, q_log, q_mul, q_normalize
from common.vehicle_constants import N_ROTORS
from common.warm_ups import warm_up
from common.wire.mavlink import MAV
from common.wire.simlink import HilSensor, Odometry, pose_covariance
from sitl.imu_kernels import TRIAD_SIZE, TRIAD_TAU, imu_sample_kernel
from sitl.plant import ContactImpulses, ContactSpread, Plant, PlantState
from sitl.sensors import ImuSample, SampleClock, SensorSuite, sensor_rng

SEA_LEVEL_HPA = 1013.25
TEMPERATURE_C = 15.0
IMU_FIELDS = 0x3F  # HIL_SENSOR_UPDATED_{X,Y,Z}ACC | {X,Y,Z}GYRO
MAG_FIELDS = 0x1C0  # HIL_SENSOR_UPDATED_{X,Y,Z}MAG
BARO_FIELDS = 0x200 | 0x800 | 0x1000  # ABS_PRESSURE | PRESSURE_ALT | TEMPERATURE
_NAN3 = (float("nan"),) * 3
_NAN4 = (float("nan"),) * 4
_ZERO3 = (0.0, 0.0, 0.0)
_ZERO6 = (0.0,) * N_ROTORS


def pressure_hpa(alt_amsl_m: float) -> float:
    """ISA pressure at an altitude (the barometric formula below 11 km)."""
    return SEA_LEVEL_HPA * float((1.0 - 2.25577e-5 * alt_amsl_m) ** 5.25588)


def state_at(a: PlantState, b: PlantState, t_us: int) -> PlantState:
    """The plant's state at t_us in (a.time_us, b.time_us]: b itself at its own time (so
    samples on the physics grid are exact), else linear in position, velocity, body rate,
    rotor speeds and tilts and geodesic in attitude between the two physics steps, the
    landed flag held from a."""
    if t_us == b.time_us:
        return b
    w = (t_us - a.time_us) / (b.time_us - a.time_us)

    def lerp(x: tuple[float, ...], y: tuple[float, ...]) -> tuple[float, ...]:
        return tuple([xi + w * (yi - xi) for xi, yi in zip(x, y, strict=True)])

    d = q_log(q_mul(q_conj(a.q_enu_flu), b.q_enu_flu))
    q = q_normalize(q_mul(a.q_enu_flu, q_exp((w * d[0], w * d[1], w * d[2]))))
    p, v, om = lerp(a.p_enu_m, b.p_enu_m), lerp(a.v_enu_m_s, b.v_enu_m_s), \
        lerp(a.omega_flu_rad_s, b.omega_flu_rad_s)
    return PlantState(t_us, (p[0], p[1], p[2]), (v[0], v[1], v[2]), q, (om[0], om[1], om[2]),
                      lerp(a.rotor_speed_rad_s, b.rotor_speed_rad_s),
                      lerp(a.tilt_rad, b.tilt_rad), a.landed)


class SensorFeed:
    """The seeded sensor models of a profile, each sampled at its own instants (a
    `SampleClock`: exact multiples of its period, optionally jittered), from the plant's
    state at that instant (`state_at` between the two physics steps around it: a sample
    carries what the vehicle did at its stamp, not up to a physics step earlier, which
    would add a latency the estimator is not told of; on the grid the step itself)."""

    def __init__(self, profile: SensorProfile, seed: int, plant: Plant, control_dt_us: int,
                 home_alt_m: float = 0.0, *,
                 imu_rate_min_hz: float = IMU_RATE_MIN_HZ) -> None:
        check_servable(profile, plant.dt_us, control_dt_us, imu_rate_min_hz=imu_rate_min_hz)
        self.profile = profile
        self.plant = plant
        self.suite = SensorSuite.from_profile(profile, seed)

        def clock(section: str) -> SampleClock:
            cfg = getattr(profile, section)
            return SampleClock(cfg.rate_hz, cfg.jitter_s,
                               sensor_rng(seed, f"{section}.jitter") if cfg.jitter_s else None)

        self.imu_clock, self.baro_clock, self.mag_clock, self.mocap_clock = \
            (clock(name) for name in ("imu", "baro", "mag", "mocap"))
        self.home_alt_m = home_alt_m
        cfg = profile.mocap
        self.mocap_cov = pose_covariance(max(cfg.position_noise_m, 1e-6) ** 2,
                                         max(cfg.attitude_noise_rad, 1e-6) ** 2)
        self._prev: PlantState | None = None
        self._mag: Vec3 | None = None  # a magnetometer sample for the next HIL_SENSOR
        self._baro_alt_m: float | None = None  # likewise the barometer's
        self._contacts = ContactImpulses()  # ground impulses since the last IMU sample
        self._spread = ContactSpread(round(profile.imu.accel.contact_spread_s * 1e6))
        self.true_f_flu_m_s2: Vec3 = (0.0, 0.0, 0.0)  # the last IMU sample's, before noise
        self.flight_start_us: int | None = None
        # The faults as windows on the simulation clock [start_us, end_us) (end None: open).
        self._faults: list[tuple[str, int, int | None, Vec3]] = []
        warm_up("sitl.imu_kernels", self._warm_up)
        # the IMU sample's machine code for its arguments' types (`compiled_for`)
        imu, draws = self.suite.imu, np.zeros((1, 6))
        self._imu_sample = compiled_for(
            imu_sample_kernel, plant.params, plant.disturbance.table, _ZERO6, _ZERO6, 0.0,
            1.0, 9.81, False, (1.0, 0.0, 0.0, 0.0), _ZERO3, _ZERO3, 1e-3, 1e-3, imu.gyro.row,
            draws, 0, imu.accel.row, draws, 0)

    def _warm_up(self) -> None:
        """The IMU sample's kernel once, resting and in flight, on scratch triads (their
        types as in a run; no draw taken from the sensors' streams)."""
        tri, draws = np.zeros(TRIAD_SIZE), np.zeros((1, 6))
        tri[TRIAD_TAU] = math.nan
        for landed in (True, False):
            imu_sample_kernel(self.plant.params, self.plant.disturbance.table, _ZERO6, _ZERO6,
                              0.0, 1.0, 9.81, landed, (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                              (0.0, 0.0, 0.0), 1e-3, 1e-3, tri, draws, 0, tri.copy(), draws, 0)

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
            mocap.queue[-1] = mocap.queue[-1]._replace(p_enu_m=_NAN3, q_enu_flu=_NAN4)

    def _deliver(self, t_us: int, out: list[HilSensor | Odometry]) -> None:
        """The poses whose latency has passed at t_us, as ODOMETRY at their capture time
        (called when the oldest is due: `period` looks first)."""
        for pose in self.suite.mocap.deliver((t_us + 0.5) * 1e-6):
            out.append(Odometry(round(pose.capture_s * 1e6), enu_to_ned(pose.p_enu_m),
                                q_enu_flu_to_ned_frd(pose.q_enu_flu), _NAN3, _NAN3,
                                MAV.MAV_ESTIMATOR_TYPE_MOCAP, self.mocap_cov))

    def _hil_sensor(self, s: PlantState) -> HilSensor:
        """The IMU sample at s.time_us (taken now), with the newest magnetometer and
        barometer samples not sent yet. Its true specific force, gyro and accelerometer
        readings (FLU) are one compiled call (`imu_sample_kernel`): `Plant.specific_force_
        flu` (the contact impulses since the last sample, over its interval), then
        `ImuModel.sample`."""
        t, dt_us = self.imu_clock.take()  # dt_us >= 1: samples are at least 1 us apart
        dv = self._contacts.take()
        if self._spread.spread_us > 0:
            dv = self._spread.take(dv, dt_us)
        plant, imu = self.plant, self.suite.imu
        speeds, tilts = s.rotor_speed_rad_s, s.tilt_rad
        if len(speeds) != N_ROTORS or len(tilts) != N_ROTORS:
            raise ValueError(f"expected {N_ROTORS} rotor speeds and tilts, got "
                             f"{len(speeds)} and {len(tilts)}")
        gyro_block, gk = imu.gyro.draws.take_row()
        accel_block, ak = imu.accel.draws.take_row()
        dt_s = dt_us * 1e-6
        f, g, a = self._imu_sample(plant.params, plant.disturbance.table, speeds, tilts,
                                   s.time_us * 1e-6, plant.mass, plant.g, s.landed,
                                   s.q_enu_flu, s.omega_flu_rad_s, dv, dt_s, dt_s,
                                   imu.gyro.row, gyro_block, gk, imu.accel.row, accel_block,
                                   ak)
        self.true_f_flu_m_s2 = f
        if self._faults:
            imu_s = self._imu_faults(t, ImuSample(t * 1e-6, g, a))
            a, g = imu_s.f_flu_m_s2, imu_s.omega_flu_rad_s
        fields = IMU_FIELDS
        mag = _NAN3
        if self._mag is not None:
            mag, self._mag = self._mag, None
            fields |= MAG_FIELDS
        pressure = alt = float("nan")
        if self._baro_alt_m is not None:
            alt, self._baro_alt_m = self._baro_alt_m, None
            pressure = pressure_hpa(alt)
            fields |= BARO_FIELDS
        # to FRD (`flu_to_frd`)
        return HilSensor(t, (a[0], -a[1], -a[2]), (g[0], -g[1], -g[2]), mag, pressure, alt,
                         TEMPERATURE_C, fields)

    def _slow_samples(self, te: int, at: PlantState) -> None:
        """The motion capture, magnetometer and barometer samples due at te (state `at`)."""
        suite = self.suite
        if self.mocap_clock.due_us == te:
            self._capture(self.mocap_clock.take()[0], at)
        if self.mag_clock.due_us == te:
            self._mag = flu_to_frd(suite.mag.sample(self.mag_clock.take()[0] * 1e-6,
                                                    at.q_enu_flu).b_flu_gauss)
        if self.baro_clock.due_us == te:
            self._baro_alt_m = self.home_alt_m + suite.baro.sample(
                self.baro_clock.take()[0] * 1e-6, at.p_enu_m).alt_m

    def period(self, states: Sequence[PlantState]) -> list[HilSensor | Odometry]:
        """The messages for these physics-step states (times increasing, each once): the
        samples due since the previous state, in time order; at one instant a pose delivered
        then goes before the IMU sample, and the magnetometer and barometer ride on the
        IMU's HIL_SENSOR (flagged in its fields)."""
        out: list[HilSensor | Odometry] = []
        for s in states:
            t = s.time_us
            prev = self._prev
            if prev is None:
                for c in (self.imu_clock, self.baro_clock, self.mag_clock, self.mocap_clock):
                    c.start(t)
            elif t <= prev.time_us:
                raise ValueError(f"sensor feed: time {t} us after {prev.time_us} us")
            self._prev = s
            self._step_samples(prev, s, out)
        return out

    def _step_samples(self, prev: PlantState | None, s: PlantState,
                      out: list[HilSensor | Odometry]) -> None:
        """`period`'s messages for the samples due in (prev, s], appended to out."""
        queue = self.suite.mocap.queue  # the poses captured, not delivered yet (`_deliver`)
        imu_c, baro_c, mag_c, mocap_c = (self.imu_clock, self.baro_clock, self.mag_clock,
                                         self.mocap_clock)
        t = s.time_us
        # `Plant.contact_dv_enu`, zero unless the step ended resting from flight
        dv = _ZERO3 if prev is None or not s.landed or prev.landed else \
            self.plant.contact_dv_enu(prev, s)
        slow_us = min(baro_c.due_us, mag_c.due_us, mocap_c.due_us)
        while True:
            imu_us = imu_c.due_us
            te = imu_us if imu_us < slow_us else slow_us
            if te > t:
                break
            at = s if prev is None or te == t else state_at(prev, s, te)
            if te == slow_us:
                self._slow_samples(te, at)
                slow_us = min(baro_c.due_us, mag_c.due_us, mocap_c.due_us)
            if imu_us == te:
                if te == t and dv is not _ZERO3:  # the step's impulse, at its end
                    self._contacts.add(dv)
                    dv = _ZERO3
                if queue and queue[0].delivered_s <= (te + 0.5) * 1e-6:
                    self._deliver(te, out)
                out.append(self._hil_sensor(at))
        if dv is not _ZERO3:  # (adding zeros changes no sum: it never holds a -0.0)
            self._contacts.add(dv)
        if queue and queue[0].delivered_s <= (t + 0.5) * 1e-6:
            self._deliver(t, out)
