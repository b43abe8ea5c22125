"""Pure, seeded sensor models of the simulator: IMU, barometer, magnetometer, motion capture.

Frames: the models work in the plant's frames, ENU world and FLU body; conversion to the
wire (NED/FRD) happens elsewhere (common.frames). Each sensor owns a numpy Generator seeded
from (seed, sensor name), so its draws do not depend on which other sensors were sampled.
The caller samples each sensor at its own period (`period_s`), passing time explicitly, at
the instants a `SampleClock` gives (exact multiples of the period, optionally jittered).

    gyro/accel:  y = sat(x + b0 + b_rw(t) + k_vib N sqrt(rate) n),  b_rw += s_rw sqrt(dt) n,
                 or with a correlation time tau (Gauss-Markov, as Gazebo classic's IMU plugin,
                 gazebo_imu_plugin.cpp addNoise, Maybeck 4-114):
                 b_rw = exp(-dt/tau) b_rw + s_rw sqrt(tau/2 (1 - exp(-2 dt/tau))) n
    baro:        h = z_enu + bias + s n
    mag:         m_flu = R(q_enu_flu)^T ned_to_enu(B_ned) + s n
    mocap:       p = p_enu + s_p n,  q = q_enu_flu * exp(s_a n),  delivered at t + latency
    gps:         p = p_enu + (s_h n, s_h n, s_v n),  v = v_enu + s_vel n  (one fix)
"""

from __future__ import annotations

import math
import zlib
from collections import deque
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from common.config.sensors import (
    AccelConfig,
    BaroConfig,
    GpsConfig,
    GyroConfig,
    ImuConfig,
    MagConfig,
    MocapConfig,
    SensorProfile,
    period_us,
)
from common.frames import ned_to_enu
from common.quaternion import Quat, Vec3, q_exp, q_mul, q_rotate_inv
from sitl.imu_kernels import (
    TRIAD_LIMIT,
    TRIAD_RANDOM_WALK,
    TRIAD_SIZE,
    TRIAD_TAU,
    TRIAD_TURN_ON,
    TRIAD_WALK,
    TRIAD_WHITE,
    triad_kernel,
)


def sensor_rng(seed: int, name: str) -> np.random.Generator:
    """A Generator that depends only on (seed, name): crc32 gives a stable name key."""
    return np.random.default_rng(np.random.SeedSequence([seed, zlib.crc32(name.encode())]))


class SampleClock:
    """When one sensor samples, in integer microseconds of the simulation clock.

    Sample k is due at round(k * 1e6 / rate_hz), computed from k with exact integers (so a
    120 Hz clock is at 8333, 16667, 25000, ... and never drifts, however long the run), then
    moved by its jitter: an integer uniform in [-jitter_s, +jitter_s] drawn from `rng` (one
    draw per sample, none without jitter), never before the previous sample.
    """

    def __init__(self, rate_hz: float, jitter_s: float = 0.0,
                 rng: np.random.Generator | None = None) -> None:
        p = period_us(rate_hz)
        self._num, self._den = p.numerator, p.denominator
        self.jitter_us = math.floor(round(jitter_s * 1e6, 6))
        if self.jitter_us and rng is None:
            raise ValueError("a jittered sample clock needs a Generator")
        self.rng = rng
        self.k = 0  # the index of the next sample
        self.due_us = 0  # the next sample's time (once started)
        self.last_us: int | None = None  # the previous sample's time
        self.started = False

    def nominal_us(self, k: int) -> int:
        """round(k * period) in us, halves up; exact for any k."""
        return (2 * k * self._num + self._den) // (2 * self._den)

    def start(self, t_us: int) -> None:
        """The first sample is the first one due at or after t_us."""
        k = max(0, t_us * self._den // self._num)
        while k > 0 and self.nominal_us(k - 1) >= t_us:
            k -= 1
        while self.nominal_us(k) < t_us:
            k += 1
        self.k = k
        self.due_us = self._jittered(k, t_us - 1)
        self.started = True

    def _jittered(self, k: int, after_us: int) -> int:
        t = self.nominal_us(k)
        if self.jitter_us:
            assert self.rng is not None
            t += int(self.rng.integers(-self.jitter_us, self.jitter_us, endpoint=True))
        return max(t, after_us + 1)

    def take(self) -> tuple[int, int]:
        """The due sample's time and the time since the previous sample (the nominal
        period for the first); the next sample is scheduled."""
        t = self.due_us
        if self.last_us is None:
            dt = self.nominal_us(self.k + 1) - self.nominal_us(self.k)
        else:
            dt = t - self.last_us
        self.last_us = t
        k = self.k = self.k + 1
        if self.jitter_us:
            self.due_us = self._jittered(k, t)
        else:  # `_jittered` without a draw
            due = (2 * k * self._num + self._den) // (2 * self._den)  # nominal_us(k)
            self.due_us = due if due > t else t + 1
        return t, dt


def _vec3(a: np.ndarray) -> Vec3:
    return (float(a[0]), float(a[1]), float(a[2]))


class _Normals:
    """Standard normal draws from `rng`, `width` per `take()`, fetched in blocks: the same
    numbers in the same order as one `rng.normal(0.0, 1.0, width)` per take (a Generator
    fills an array draw by draw), without numpy's cost of a call per sample."""

    def __init__(self, rng: np.random.Generator, width: int, block: int = 256) -> None:
        self.rng = rng
        self.width = width
        self.block = block
        self._block = np.empty((0, width))
        self._rows: list[list[float]] | None = []
        self._next = 0

    def take(self) -> list[float]:
        block, i = self.take_row()
        rows = self._rows
        if rows is None:
            rows = self._rows = block.tolist()
        return rows[i]

    def take_row(self) -> tuple[np.ndarray, int]:
        """The next draws as (the block that holds them, their row in it), for a kernel."""
        i = self._next
        if i == len(self._block):
            self._block = self.rng.normal(0.0, 1.0, (self.block, self.width))
            self._rows = None
            i = 0
        self._next = i + 1
        return self._block, i


class _Triad:
    """One three-axis inertial sensor: turn-on bias, bias random walk (unbounded, or
    Gauss-Markov with a correlation time), white noise, range; its state and settings in
    one row (`sitl.imu_kernels.TRIAD_*`) for the compiled sample."""

    def __init__(self, rng: np.random.Generator, *, white_sigma: float, turn_on_sigma: float,
                 random_walk: float, limit: float,
                 correlation_time_s: float | None = None) -> None:
        self.rng = rng
        self.white_sigma = white_sigma
        self.random_walk = random_walk
        self.limit = limit
        self.correlation_time_s = correlation_time_s
        self.turn_on_bias: Vec3 = _vec3(rng.normal(0.0, 1.0, 3) * turn_on_sigma)
        self.row = np.zeros(TRIAD_SIZE)
        self.row[TRIAD_TURN_ON:TRIAD_TURN_ON + 3] = self.turn_on_bias
        self.row[TRIAD_WHITE] = white_sigma
        self.row[TRIAD_RANDOM_WALK] = random_walk
        self.row[TRIAD_LIMIT] = limit
        self.row[TRIAD_TAU] = math.nan if correlation_time_s is None else correlation_time_s
        self.draws = _Normals(rng, 6)  # always six per sample: the stream stays aligned

    @property
    def walk(self) -> Vec3:
        return _vec3(self.row[TRIAD_WALK:TRIAD_WALK + 3])

    @property
    def bias(self) -> Vec3:
        b, w = self.turn_on_bias, self.walk
        return (b[0] + w[0], b[1] + w[1], b[2] + w[2])

    def sample(self, truth: Vec3, dt_s: float) -> Vec3:
        """One reading (`sitl.imu_kernels.triad_kernel`): the same floats, to the last bit,
        as numpy's element-wise form."""
        if not dt_s > 0.0:
            raise ValueError(f"dt_s must be > 0, got {dt_s!r}")
        block, k = self.draws.take_row()
        return triad_kernel(self.row, block, k, float(truth[0]), float(truth[1]),
                            float(truth[2]), dt_s)


class ImuSample(NamedTuple):
    t_s: float
    omega_flu_rad_s: Vec3
    f_flu_m_s2: Vec3


class ImuModel:
    """Gyro and accelerometer in FLU; white sigma = vibration_factor * N * sqrt(rate_hz)."""

    def __init__(self, cfg: ImuConfig, seed: int) -> None:
        self.cfg = cfg
        self.gyro = _gyro(cfg.gyro, cfg, sensor_rng(seed, "imu.gyro"))
        self.accel = _accel(cfg.accel, cfg, sensor_rng(seed, "imu.accel"))

    @property
    def period_s(self) -> float:
        return 1.0 / self.cfg.rate_hz

    def sample(self, t_s: float, dt_s: float, omega_flu_rad_s: Vec3,
               f_flu_m_s2: Vec3) -> ImuSample:
        """One sample from the true body rate and specific force (Plant.specific_force_flu)."""
        return ImuSample(t_s, self.gyro.sample(omega_flu_rad_s, dt_s),
                         self.accel.sample(f_flu_m_s2, dt_s))


def _gyro(g: GyroConfig, imu: ImuConfig, rng: np.random.Generator) -> _Triad:
    return _Triad(rng, white_sigma=imu.gyro_sigma_rad_s,
                  turn_on_sigma=g.turn_on_bias_sigma_rad_s,
                  random_walk=g.bias_random_walk_rad_s2_sqrt_hz, limit=g.range_rad_s,
                  correlation_time_s=g.bias_correlation_time_s)


def _accel(a: AccelConfig, imu: ImuConfig, rng: np.random.Generator) -> _Triad:
    return _Triad(rng, white_sigma=imu.accel_sigma_m_s2,
                  turn_on_sigma=a.turn_on_bias_sigma_m_s2,
                  random_walk=a.bias_random_walk_m_s3_sqrt_hz, limit=a.range_m_s2,
                  correlation_time_s=a.bias_correlation_time_s)


class BaroSample(NamedTuple):
    t_s: float
    alt_m: float  # pressure altitude above the home point (ENU up)


class BaroModel:
    """Pressure altitude: z_enu + bias + white noise (pressure conversion is the link's)."""

    def __init__(self, cfg: BaroConfig, seed: int) -> None:
        self.cfg = cfg
        self.rng = sensor_rng(seed, "baro")

    @property
    def period_s(self) -> float:
        return 1.0 / self.cfg.rate_hz

    def sample(self, t_s: float, p_enu_m: Vec3) -> BaroSample:
        n = float(self.rng.normal(0.0, 1.0))
        alt = p_enu_m[2] + self.cfg.bias_m
        if self.cfg.noise_m > 0.0:
            alt += self.cfg.noise_m * n
        return BaroSample(t_s, alt)


class MagSample(NamedTuple):
    t_s: float
    b_flu_gauss: Vec3


class MagModel:
    """The fixed earth field (given in NED) seen in FLU, plus white noise."""

    def __init__(self, cfg: MagConfig, seed: int) -> None:
        self.cfg = cfg
        self.rng = sensor_rng(seed, "mag")
        self.b_enu_gauss: Vec3 = ned_to_enu(cfg.field_ned_gauss)

    @property
    def period_s(self) -> float:
        return 1.0 / self.cfg.rate_hz

    def sample(self, t_s: float, q_enu_flu: Quat) -> MagSample:
        n = self.rng.normal(0.0, 1.0, 3).tolist()
        b = q_rotate_inv(q_enu_flu, self.b_enu_gauss)
        s = self.cfg.noise_gauss
        if s > 0.0:  # element by element, as numpy's b + s n
            b = (float(b[0]) + s * n[0], float(b[1]) + s * n[1], float(b[2]) + s * n[2])
        return MagSample(t_s, b)


class PoseDelivery(NamedTuple):
    capture_s: float  # when the pose was measured
    delivered_s: float  # capture_s + latency_s: when the receiver gets it
    p_enu_m: Vec3
    q_enu_flu: Quat


class MocapModel:
    """External pose: noisy capture, seeded dropouts, a FIFO that delivers after latency_s."""

    def __init__(self, cfg: MocapConfig, seed: int) -> None:
        self.cfg = cfg
        self.rng = sensor_rng(seed, "mocap")
        self.queue: deque[PoseDelivery] = deque()
        self.captures = 0
        self.dropped = 0

    @property
    def period_s(self) -> float:
        return 1.0 / self.cfg.rate_hz

    def capture(self, t_s: float, p_enu_m: Vec3, q_enu_flu: Quat) -> None:
        """Measure the true pose at t_s (call once per period) and queue it unless dropped.

        Attitude noise is a body-frame rotation vector d ~ N(0, s^2 I): q = q_true exp(d).
        """
        if self.queue and t_s < self.queue[-1].capture_s:
            raise ValueError(f"capture times must not decrease: {t_s} after "
                             f"{self.queue[-1].capture_s}")
        u = float(self.rng.random())  # fixed draw count per capture, dropped or not
        n = self.rng.normal(0.0, 1.0, 6).tolist()
        self.captures += 1
        if u < self.cfg.dropout_probability:
            self.dropped += 1
            return
        p, q = p_enu_m, q_enu_flu
        sp, sa = self.cfg.position_noise_m, self.cfg.attitude_noise_rad
        if sp > 0.0:  # element by element, as numpy's p + s n
            p = (float(p_enu_m[0]) + sp * n[0], float(p_enu_m[1]) + sp * n[1],
                 float(p_enu_m[2]) + sp * n[2])
        if sa > 0.0:
            q = q_mul(q_enu_flu, q_exp((sa * n[3], sa * n[4], sa * n[5])))
        self.queue.append(PoseDelivery(t_s, t_s + self.cfg.latency_s, p, q))

    def deliver(self, t_s: float) -> list[PoseDelivery]:
        """Every queued capture whose delivery time is <= t_s, oldest first."""
        out: list[PoseDelivery] = []
        while self.queue and self.queue[0].delivered_s <= t_s:
            out.append(self.queue.popleft())
        return out


class GpsModel:
    """A GNSS fix: white noise on position (horizontal, altitude) and NED velocity."""

    def __init__(self, cfg: GpsConfig, seed: int) -> None:
        self.cfg = cfg
        self.rng = sensor_rng(seed, "gps")

    def sample(self, p_enu_m: Vec3, v_enu_m_s: Vec3) -> tuple[Vec3, Vec3]:
        """The fix's position and velocity (ENU), six draws per fix."""
        n = self.rng.normal(0.0, 1.0, 6)
        c = self.cfg
        vn, ve, vd = c.velocity_noise_ned_m_s
        h, z = c.position_noise_m, c.altitude_noise_m
        return ((p_enu_m[0] + h * n[0], p_enu_m[1] + h * n[1], p_enu_m[2] + z * n[2]),
                (v_enu_m_s[0] + ve * n[3], v_enu_m_s[1] + vn * n[4],
                 v_enu_m_s[2] + vd * n[5]))


@dataclass
class SensorSuite:
    """The four models of one profile, each with its own seeded stream."""

    imu: ImuModel
    baro: BaroModel
    mag: MagModel
    mocap: MocapModel

    @classmethod
    def from_profile(cls, profile: SensorProfile, seed: int) -> SensorSuite:
        return cls(ImuModel(profile.imu, seed), BaroModel(profile.baro, seed),
                   MagModel(profile.mag, seed), MocapModel(profile.mocap, seed))
