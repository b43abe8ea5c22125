"""The IMU model's per-sample arithmetic as compiled kernels (`sitl.sensors.ImuModel`,
`sitl.sensor_feed.SensorFeed`): one three-axis triad's reading, and a whole IMU sample from
the plant's state (its specific force, then the gyro and accelerometer triads) in one call.

The same operations in the same order as the scalar Python they replace (no fastmath), so the
readings are the same floats to the last bit. A triad's row (TRIAD_*) holds its turn-on bias,
its bias walk (updated in place), the white noise, the random walk, the range and the
correlation time (NaN: an unbounded walk); its draws are rows of six standard normals.
"""

from __future__ import annotations

import math

import numpy as np
from numba import literal_unroll

from common.jit import njit
from common.vehicle_constants import N_ROTORS
from sitl.plant_kernels import flight_force_kernel, rotate_inv

TRIAD_TURN_ON = 0  # 3: the turn-on bias
TRIAD_WALK = 3  # 3: the bias walk, updated by each sample
TRIAD_WHITE = 6  # the white noise's sigma
TRIAD_RANDOM_WALK = 7  # the walk's density
TRIAD_LIMIT = 8  # the range, +-
TRIAD_TAU = 9  # the walk's correlation time in s (NaN: unbounded)
TRIAD_SIZE = 10


@njit
def _clip(y: float, lim: float) -> float:
    """min(max(y, -lim), lim) as Python's builtins give it (a NaN stays NaN)."""
    m = -lim if -lim > y else y
    return lim if lim < m else m


@njit
def triad_kernel(tri: np.ndarray, draws: np.ndarray, k: int, x0: float, x1: float, x2: float,
                 dt_s: float) -> tuple[float, float, float]:
    """One reading of the triad `tri` of the truth (x0, x1, x2) over dt_s, with the draws of
    row k: the walk advanced (in tri), then truth + turn-on bias + walk + white noise,
    clipped to the range."""
    d = draws[k]
    tau = tri[TRIAD_TAU]
    w0, w1, w2 = tri[TRIAD_WALK], tri[TRIAD_WALK + 1], tri[TRIAD_WALK + 2]
    if math.isnan(tau):
        c = tri[TRIAD_RANDOM_WALK] * math.sqrt(dt_s)
        w0, w1, w2 = w0 + c * d[3], w1 + c * d[4], w2 + c * d[5]
    else:  # the exact discretisation of db/dt = -b/tau + s_rw w over dt
        sigma = tri[TRIAD_RANDOM_WALK] * math.sqrt(-0.5 * tau * math.expm1(-2.0 * dt_s / tau))
        a = math.exp(-dt_s / tau)
        w0, w1, w2 = a * w0 + sigma * d[3], a * w1 + sigma * d[4], a * w2 + sigma * d[5]
    tri[TRIAD_WALK], tri[TRIAD_WALK + 1], tri[TRIAD_WALK + 2] = w0, w1, w2
    y0 = x0 + tri[TRIAD_TURN_ON] + w0
    y1 = x1 + tri[TRIAD_TURN_ON + 1] + w1
    y2 = x2 + tri[TRIAD_TURN_ON + 2] + w2
    s = tri[TRIAD_WHITE]
    if s > 0.0:
        y0, y1, y2 = y0 + s * d[0], y1 + s * d[1], y2 + s * d[2]
    lim = tri[TRIAD_LIMIT]
    return (_clip(y0, lim), _clip(y1, lim), _clip(y2, lim))


@njit
def imu_sample_kernel(pp: np.ndarray, dist: np.ndarray, speeds_rad_s: tuple[float, ...],
                      tilts_rad: tuple[float, ...], state_t_s: float, mass: float, g: float,
                      landed: bool,
                      q_enu_flu: tuple[float, float, float, float],
                      omega_flu_rad_s: tuple[float, float, float],
                      contact_dv_enu: tuple[float, float, float], interval_s: float,
                      dt_s: float, gyro: np.ndarray, gyro_draws: np.ndarray, gk: int,
                      accel: np.ndarray, accel_draws: np.ndarray, ak: int
                      ) -> tuple[tuple[float, float, float], tuple[float, float, float],
                                 tuple[float, float, float]]:
    """(true specific force, gyro reading, accelerometer reading), FLU: `Plant.specific_
    force_flu` of the state (resting: R^T g up; in flight the rotor and disturbance force
    per mass of the rotors' N_ROTORS speeds and tilts at state_t_s; plus the contact impulse
    over interval_s), then the gyro's and the accelerometer's `triad_kernel` over dt_s."""
    if landed:
        f = rotate_inv(q_enu_flu, (0.0, 0.0, g))
    else:
        actuators = np.empty(2 * N_ROTORS)  # as np.array((*speeds, *tilts), float64)
        k = 0
        for x in literal_unroll(speeds_rad_s):
            actuators[k] = x
            k += 1
        for x in literal_unroll(tilts_rad):
            actuators[k] = x
            k += 1
        f = flight_force_kernel(pp, dist, actuators, state_t_s, mass)
    dv = contact_dv_enu
    if not (dv[0] == 0.0 and dv[1] == 0.0 and dv[2] == 0.0):
        h = interval_s
        j = rotate_inv(q_enu_flu, (dv[0] / h, dv[1] / h, dv[2] / h))
        f = (f[0] + j[0], f[1] + j[1], f[2] + j[2])
    w = omega_flu_rad_s
    gyro_y = triad_kernel(gyro, gyro_draws, gk, w[0], w[1], w[2], dt_s)
    accel_y = triad_kernel(accel, accel_draws, ak, f[0], f[1], f[2], dt_s)
    return f, gyro_y, accel_y
