"""Error-state (multiplicative) EKF: IMU-driven strapdown fusing a delayed external pose.

Frames and units: world ENU (g_W = [0, 0, -g]), body FLU, Hamilton quaternions (w, x, y, z),
q_enu_flu body to world, time in integer microseconds. The accelerometer measures the
specific force f = R^T (a_W - g_W) + b_a + n, the gyro omega + b_g + n.

Nominal state x = (p, v, q, b_g, b_a); error state dx = [dp, dv, dtheta, db_g, db_a] with the
local (body) attitude error q = q_hat * exp(dtheta) (Sola, "Quaternion kinematics for the
error-state Kalman filter", 2017, sec. 5.3 and 7). The pose is plain quaternion + vector
(not a dual quaternion): position and attitude are gated and fused as separate 3-vectors.

- Strapdown (Sola sec. 5.4.1, eq. 260; each sample held over the interval ending at its t_us,
  the specific force rotated to mid-interval): p += v dt + a_W dt^2/2, v += a_W dt,
  q = q exp((w_m - b_g) dt).
- Covariance (Sola sec. 5.4.3, eq. 269-274): P = F P F^T + Q with F = I + [dp/dv = I dt,
  dv/dtheta = -R [a]x dt, dv/db_a = -R dt, dtheta/dtheta = I - [w dt]x, dtheta/db_g = -I dt].
  Discretisation: per IMU sample, delta-velocity variance (accel_noise dt)^2 and delta-angle
  variance (gyro_noise dt)^2 (Sola eq. 271-272, EKF2's daxVar/dvxVar: the settings are the
  per-sample sigmas); bias random walks sigma^2 dt (Sola eq. 273-274: densities).
- Update: Joseph form, symmetrised, diagonal floors; injection and reset Jacobian
  G = I - [dtheta/2]x on the attitude block (Sola sec. 6.2-6.3, eq. 282-287).
- Covariance steps every cov_period_s of IMU time (EKF2_PREDICT_US) from the interval's
  deltas, and before every fusion; the nominal state integrates every sample.
- Delayed fusion as EKF2 (EKF2_EV_DELAY): the filter runs at the horizon
  t_h = newest IMU - pose_delay_s on the buffered IMU samples; a pose is fused at the
  buffered sample nearest its capture time. Output predictor: the output state integrates
  each new sample once; a horizon correction is carried to it by the linearised transition
  over the buffered interval (no lag, no EKF2-style feedback time constant), and every
  output_resync_s (and after resets) the buffered samples are re-propagated exactly. Both
  agree within 1 um; re-propagating after every fusion costs ~2x (bench_estimator.py).
- Gates (EKF2 test ratio): max over axes of innov^2 / (gate^2 S) > 1 refuses position or
  attitude (separately). A pose counts as fused when both parts pass, else as rejected (a
  passing part is still fused). After pose_reset_timeout_s of refused position (attitude),
  the position (attitude) resets to the pose, as EKF2 resets to vision after
  reset_timeout_max.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from common.quaternion import Quat, Vec3, q_conj, q_exp, q_log, q_mul, q_rotate, q_rotate_inv
from fcu.tracker import VehicleState

_N = 15
# (p, v, q, b_g, b_a) as one flat tuple of 16 floats
_State = tuple[float, float, float, float, float, float, float, float, float, float,
               float, float, float, float, float, float]

_I15 = np.eye(_N)
_H_POS = _I15[[0, 1, 2]]  # measurement selectors
_H_ATT = _I15[[6, 7, 8]]
_H_BOTH = _I15[[0, 1, 2, 6, 7, 8]]
_G_IDX = np.array([6 * _N + 7, 6 * _N + 8, 7 * _N + 6, 7 * _N + 8, 8 * _N + 6, 8 * _N + 7])


def _flat_indices() -> np.ndarray:
    """Flat indices into F of its 60 time-varying entries, in _cov_step's order."""
    rc = [(i, 3 + i) for i in range(3)]
    for r0, c0 in ((0, 6), (0, 12), (3, 6), (3, 9), (3, 12), (6, 6)):
        rc += [(r0 + i, c0 + j) for i in range(3) for j in range(3)]
    rc += [(6 + i, 9 + i) for i in range(3)]
    return np.array([r * _N + c for r, c in rc])


_F_IDX = _flat_indices()


@dataclass(frozen=True)
class EstimatorSettings:
    gravity_m_s2: float = 9.81
    gyro_noise_rad_s: float = 0.015  # EKF2_GYR_NOISE: per-sample sigma, angle var (sigma dt)^2
    accel_noise_m_s2: float = 0.35  # EKF2_ACC_NOISE: per-sample sigma, dv var (sigma dt)^2
    gyro_bias_noise_rad_s2: float = 1e-3  # EKF2_GYR_B_NOISE as a density: var sigma^2 dt
    accel_bias_noise_m_s3: float = 3e-3  # EKF2_ACC_B_NOISE as a density: var sigma^2 dt
    pose_pos_noise_m: float = 0.001  # floor on the position sigma (EKF2_EVP_NOISE)
    pose_att_noise_rad: float = 0.002  # floor on the attitude sigma (EKF2_EVA_NOISE)
    pose_delay_s: float = 0.02  # fusion horizon behind the newest IMU sample (EKF2_EV_DELAY)
    pose_gate_sd: float = 5.0  # innovation gate in sd (EKF2_EV_POS_GATE)
    align_time_s: float = 1.0  # stationary time on the ground before aligned
    align_block_s: float = 0.1  # stationarity is tested on blocks of this length
    align_noise_factor: float = 3.0  # a block is still if each axis sd <= factor * noise
    align_gyro_max_rad_s: float = 0.05  # and |mean gyro| below this (turn-on bias allowed)
    align_accel_change_m_s2: float = 0.15  # and its mean f within this of the window's
    align_pose_max_age_s: float = 0.5  # the initialising pose must be this recent
    align_in_flight: bool = False  # align on the first pose, no stationary test, zero biases
    init_vel_sd_m_s: float = 0.05  # initial velocity sd on the ground
    init_vel_sd_in_flight_m_s: float = 1.0  # initial velocity sd when aligned in flight
    init_gyro_bias_sd_rad_s: float = 0.01  # gyro bias sd in flight (ground: from the window)
    init_accel_bias_sd_m_s2: float = 0.1  # initial accel bias sd
    pose_reset_timeout_s: float = 1.0  # refused this long: reset to the pose (EKF2 7 s)
    pose_queue_max: int = 64  # queued poses beyond this are refused
    converged_pos_sd_m: float = 0.002  # converged (arming allowed): pos sd below this ...
    converged_vel_sd_m_s: float = 0.01  # ... velocity sd below this ...
    converged_att_sd_rad: float = 0.002  # ... and attitude sd below this
    healthy_pos_sd_max_m: float = 10.0  # healthy only while pos sd below this
    healthy_vel_sd_max_m_s: float = 10.0  # ... velocity sd below this
    healthy_att_sd_max_rad: float = 0.5  # ... attitude sd below this
    var_max: float = 1e8  # variances are clamped (row/column scaled) below this
    cov_period_s: float = 0.01  # covariance predicted over this much IMU time (EKF2_PREDICT_US)
    output_repropagate: bool = False  # re-propagate every buffered sample after each fusion
    output_resync_s: float = 0.1  # else linear correction, exact re-propagation this often

    def __post_init__(self) -> None:
        for name in ("gravity_m_s2", "gyro_noise_rad_s", "accel_noise_m_s2",
                     "pose_pos_noise_m", "pose_att_noise_rad", "pose_gate_sd",
                     "align_block_s", "align_noise_factor", "align_gyro_max_rad_s",
                     "align_accel_change_m_s2", "align_pose_max_age_s", "init_vel_sd_m_s",
                     "init_vel_sd_in_flight_m_s", "init_gyro_bias_sd_rad_s",
                     "init_accel_bias_sd_m_s2", "pose_reset_timeout_s", "converged_pos_sd_m",
                     "converged_vel_sd_m_s",
                     "converged_att_sd_rad", "healthy_pos_sd_max_m", "healthy_vel_sd_max_m_s",
                     "healthy_att_sd_max_rad", "var_max"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0.0):
                raise ValueError(f"EstimatorSettings.{name} must be finite and > 0, got {v!r}")
        for name in ("gyro_bias_noise_rad_s2", "accel_bias_noise_m_s3", "pose_delay_s",
                     "align_time_s", "cov_period_s", "output_resync_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise ValueError(f"EstimatorSettings.{name} must be finite and >= 0, got {v!r}")
        if self.pose_queue_max < 1:
            raise ValueError("EstimatorSettings.pose_queue_max must be >= 1")


class ImuInput(NamedTuple):
    t_us: int
    omega_flu_rad_s: Vec3
    f_flu_m_s2: Vec3


class PoseInput(NamedTuple):
    capture_us: int  # when the pose was measured (before its latency)
    p_enu_m: Vec3
    q_enu_flu: Quat
    pos_var_m2: float = math.nan  # per-axis variance from the sender (NaN: settings)
    att_var_rad2: float = math.nan


class EstimatorHealth(NamedTuple):
    """The part of the status the flight checks every period (Estimator.health)."""

    aligned: bool
    converged: bool
    healthy: bool
    rejected_in_row: int
    last_fusion_us: int


class EstimatorStatus(NamedTuple):
    t_us: int
    aligned: bool
    converged: bool  # aligned and pos/vel/att sd below the settings' thresholds
    pos_sd_m: Vec3
    vel_sd_m_s: Vec3
    att_sd_rad: Vec3
    gyro_bias_sd: Vec3
    accel_bias_sd: Vec3
    gyro_bias_rad_s: Vec3
    accel_bias_m_s2: Vec3
    pos_innov_m: Vec3  # last pose's innovations (fused or not)
    att_innov_rad: Vec3
    pos_test_ratio: float  # max over axes of innov^2 / (gate^2 S)
    att_test_ratio: float
    rejected_in_row: int  # consecutive poses refused (in part) by the gate
    last_fusion_us: int  # capture time of the last fused pose (-1 none)
    fused: int
    rejected: int
    healthy: bool  # aligned, finite, SPD, sd below the blow-up limits
    imu_ignored: int = 0  # IMU samples refused (non-finite, time not increasing)
    pose_ignored: int = 0  # poses refused (non-finite, too old, future, queue full)
    resets: int = 0  # position or attitude resets to the pose after the gate timeout


_ZERO3: Vec3 = (0.0, 0.0, 0.0)


def _strapdown(x: _State, w: Vec3, f: Vec3, dt: float, g: float) -> _State:
    """One IMU sample over dt (Sola eq. 260), specific force rotated to mid-interval."""
    (px, py, pz, vx, vy, vz, qw, qx, qy, qz, bgx, bgy, bgz, bax, bay, baz) = x
    rx = (w[0] - bgx) * dt
    ry = (w[1] - bgy) * dt
    rz = (w[2] - bgz) * dt
    ax = f[0] - bax
    ay = f[1] - bay
    az = f[2] - baz
    mx = ax + 0.5 * (ry * az - rz * ay)
    my = ay + 0.5 * (rz * ax - rx * az)
    mz = az + 0.5 * (rx * ay - ry * ax)
    tx = 2.0 * (qy * mz - qz * my)
    ty = 2.0 * (qz * mx - qx * mz)
    tz = 2.0 * (qx * my - qy * mx)
    awx = mx + qw * tx + qy * tz - qz * ty
    awy = my + qw * ty + qz * tx - qx * tz
    awz = mz + qw * tz + qx * ty - qy * tx - g
    hdt = 0.5 * dt
    px += (vx + hdt * awx) * dt
    py += (vy + hdt * awy) * dt
    pz += (vz + hdt * awz) * dt
    vx += awx * dt
    vy += awy * dt
    vz += awz * dt
    h2 = 0.25 * (rx * rx + ry * ry + rz * rz)
    if h2 < 1e-4:
        c = 1.0 - h2 * (0.5 - h2 / 24.0)
        s = 0.5 * (1.0 - h2 * (1.0 / 6.0 - h2 / 120.0))
    else:
        h = math.sqrt(h2)
        c = math.cos(h)
        s = 0.5 * math.sin(h) / h
    dx = s * rx
    dy = s * ry
    dz = s * rz
    nw = qw * c - qx * dx - qy * dy - qz * dz
    nx = qw * dx + qx * c + qy * dz - qz * dy
    ny = qw * dy - qx * dz + qy * c + qz * dx
    nz = qw * dz + qx * dy - qy * dx + qz * c
    k = 1.0 / math.sqrt(nw * nw + nx * nx + ny * ny + nz * nz)
    return (px, py, pz, vx, vy, vz, nw * k, nx * k, ny * k, nz * k,
            bgx, bgy, bgz, bax, bay, baz)


class _Block(NamedTuple):
    n: int
    sw: Vec3  # sum of gyro samples
    sf: Vec3  # sum of accel samples


class Estimator:
    """The filter; feed on_imu and on_pose in arrival order, read output() and status()."""

    def __init__(self, settings: EstimatorSettings = EstimatorSettings()) -> None:
        self.settings = settings
        s = settings
        self._g = s.gravity_m_s2
        self._delay_us = round(s.pose_delay_s * 1e6)
        self._gate2 = s.pose_gate_sd * s.pose_gate_sd
        self._r_pos_floor = s.pose_pos_noise_m ** 2
        self._r_att_floor = s.pose_att_noise_rad ** 2
        self._block_us = round(s.align_block_s * 1e6)
        self._align_us = round(s.align_time_s * 1e6)
        self._timeout_us = round(s.pose_reset_timeout_s * 1e6)
        self._cov_us = round(s.cov_period_s * 1e6)
        self._resync_us = round(s.output_resync_s * 1e6)
        self._var_min = np.array([1e-14] * 3 + [1e-14] * 3 + [1e-14] * 3 + [1e-16] * 6)
        self.reset()

    # ------------------------------------------------------------------------------------
    # State

    def reset(self) -> None:
        """Back to unaligned: every state, buffer and counter cleared."""
        self._aligned = False
        self._last_t = -1
        self._last_w: Vec3 = _ZERO3
        self._dt_us = 1000  # nominal IMU period (the shortest interval seen)
        self._dt_seen = False
        self._pending: deque[ImuInput] = deque()  # samples newer than the horizon
        self._poses: list[PoseInput] = []  # queued, by capture time
        self._latest_pose: PoseInput | None = None
        # alignment
        self._blocks: deque[_Block] = deque()
        self._blk_t0 = -1
        self._blk_n = 0
        self._blk_sw = [0.0, 0.0, 0.0]
        self._blk_sw2 = [0.0, 0.0, 0.0]
        self._blk_sf = [0.0, 0.0, 0.0]
        self._blk_sf2 = [0.0, 0.0, 0.0]
        # horizon (filter) and output states
        zero16 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                  0.0)
        self._h_x: _State = zero16
        self._h_t = -1
        self._o_x: _State = zero16
        self._o_t = -1
        self._P = np.zeros((_N, _N))
        self._F = np.eye(_N)
        self._F_flat = self._F.reshape(-1)
        self._n_pred = 0
        self._c_x: _State = zero16  # horizon state at the last covariance step
        self._c_t = -1
        self._c_dt2 = 0.0  # sum of dt^2 since then
        self._resync_t = -1  # time of the last exact output re-propagation
        # fusion bookkeeping
        self._pos_innov: Vec3 = _ZERO3
        self._att_innov: Vec3 = _ZERO3
        self._pos_ratio = 0.0
        self._att_ratio = 0.0
        self._rejected_in_row = 0
        self._last_fusion_us = -1
        self._last_capture_us = -1
        self._last_pos_fuse_us = -1
        self._last_att_fuse_us = -1
        self._fused = 0
        self._rejected = 0
        self._imu_ignored = 0
        self._pose_ignored = 0
        self._resets = 0

    @property
    def aligned(self) -> bool:
        return self._aligned

    @property
    def covariance(self) -> np.ndarray:
        """A copy of the 15x15 error-state covariance at the horizon."""
        return self._P.copy()

    # ------------------------------------------------------------------------------------
    # Inputs

    def on_imu(self, s: ImuInput) -> None:
        """One IMU sample: buffer it, advance the horizon, propagate the output to s.t_us."""
        w = s.omega_flu_rad_s
        f = s.f_flu_m_s2
        try:
            t = s.t_us if type(s.t_us) is int else int(s.t_us)
            ok = math.isfinite(w[0] + w[1] + w[2] + f[0] + f[1] + f[2]) and t > self._last_t
        except (TypeError, IndexError, OverflowError, ValueError):
            ok = False
        if not ok:
            self._imu_ignored += 1
            return
        if t is not s.t_us:
            s = s._replace(t_us=t)
        if self._last_t >= 0:  # the nominal period: the shortest interval (a gap is no period)
            dt = t - self._last_t
            self._dt_us = dt if not self._dt_seen else min(self._dt_us, dt)
            self._dt_seen = True
        self._last_t = t
        self._last_w = w
        pend = self._pending
        pend.append(s)
        if not self._aligned:
            self._align_step(s)
            return
        h_lim = t - self._delay_us
        half = self._dt_us >> 1
        while pend and pend[0].t_us <= h_lim:
            self._predict(pend.popleft())
            if self._poses and self._poses[0].capture_us <= self._h_t + half:
                self._fuse_due()
        if not pend:
            self._o_x = self._h_x
            self._o_t = self._h_t
        elif self._o_t < t:
            self._o_x = _strapdown(self._o_x, w, f, (t - self._o_t) * 1e-6, self._g)
            self._o_t = t

    def on_pose(self, m: PoseInput) -> None:
        """Queue a pose; it is fused when the horizon reaches capture_us (in time order)."""
        checked = self._check_pose(m)
        if checked is None:
            self._pose_ignored += 1
            return
        m = checked
        half = self._dt_us >> 1
        c = m.capture_us
        if self._last_t < 0 or c > self._last_t + half:  # no IMU yet, or in the future
            self._pose_ignored += 1
            return
        if not self._aligned:
            if self._latest_pose is None or c > self._latest_pose.capture_us:
                self._latest_pose = m
            self._queue(m)
            return
        if c < self._h_t - half or c <= self._last_capture_us:  # behind the horizon
            self._pose_ignored += 1
            return
        if c <= self._h_t + half:
            self._fuse(m)
            return
        self._queue(m)

    def _check_pose(self, m: PoseInput) -> PoseInput | None:
        try:
            p = (float(m.p_enu_m[0]), float(m.p_enu_m[1]), float(m.p_enu_m[2]))
            q = (float(m.q_enu_flu[0]), float(m.q_enu_flu[1]), float(m.q_enu_flu[2]),
                 float(m.q_enu_flu[3]))
            c = int(m.capture_us)
        except (TypeError, IndexError, ValueError, OverflowError):
            return None
        if not math.isfinite(p[0] + p[1] + p[2] + q[0] + q[1] + q[2] + q[3]):
            return None
        n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
        if not 0.9 < n < 1.1:
            return None
        q = (q[0] / n, q[1] / n, q[2] / n, q[3] / n)
        return PoseInput(c, p, q, float(m.pos_var_m2), float(m.att_var_rad2))

    def _queue(self, m: PoseInput) -> None:
        bisect.insort(self._poses, m, key=lambda e: e.capture_us)
        if len(self._poses) > self.settings.pose_queue_max:
            self._poses.pop(0)
            self._pose_ignored += 1

    # ------------------------------------------------------------------------------------
    # Alignment

    def _align_step(self, s: ImuInput) -> None:
        pend = self._pending
        h_lim = s.t_us - self._delay_us
        while len(pend) >= 2 and pend[1].t_us <= h_lim:
            pend.popleft()
        half = self._dt_us >> 1
        while self._poses and self._poses[0].capture_us < h_lim - half and len(self._poses) > 1:
            self._poses.pop(0)
        if self.settings.align_in_flight:
            if self._latest_pose is not None and len(pend) >= 1 and pend[0].t_us <= h_lim:
                self._initialise(None)
            return
        self._block_add(s)
        if self._latest_pose is None or pend[0].t_us > h_lim:
            return
        dur = sum(b.n for b in self._blocks) * self._dt_us
        if dur >= self._align_us and dur > 0:
            age = s.t_us - self._latest_pose.capture_us
            if age <= self.settings.align_pose_max_age_s * 1e6:
                self._initialise(self._blocks)

    def _block_add(self, s: ImuInput) -> None:
        w = s.omega_flu_rad_s
        f = s.f_flu_m_s2
        if self._blk_n == 0:
            self._blk_t0 = s.t_us
        self._blk_n += 1
        for i in range(3):
            self._blk_sw[i] += w[i]
            self._blk_sw2[i] += w[i] * w[i]
            self._blk_sf[i] += f[i]
            self._blk_sf2[i] += f[i] * f[i]
        if s.t_us - self._blk_t0 + self._dt_us < self._block_us:
            return
        st = self.settings
        n = self._blk_n
        mw = [a / n for a in self._blk_sw]
        mf = [a / n for a in self._blk_sf]
        vw = max(self._blk_sw2[i] / n - mw[i] * mw[i] for i in range(3))
        vf = max(self._blk_sf2[i] / n - mf[i] * mf[i] for i in range(3))
        still = (vw <= (st.align_noise_factor * st.gyro_noise_rad_s) ** 2
                 and vf <= (st.align_noise_factor * st.accel_noise_m_s2) ** 2
                 and math.sqrt(mw[0] ** 2 + mw[1] ** 2 + mw[2] ** 2) <= st.align_gyro_max_rad_s
                 and abs(math.sqrt(mf[0] ** 2 + mf[1] ** 2 + mf[2] ** 2) - self._g)
                 <= 10.0 * st.align_accel_change_m_s2)
        if still and self._blocks:
            nt = sum(b.n for b in self._blocks)
            wf = [sum(b.sf[i] for b in self._blocks) / nt for i in range(3)]
            still = math.dist(wf, mf) <= st.align_accel_change_m_s2
        blk = _Block(n, (self._blk_sw[0], self._blk_sw[1], self._blk_sw[2]),
                     (self._blk_sf[0], self._blk_sf[1], self._blk_sf[2]))
        if still:
            self._blocks.append(blk)
            keep = self._align_us + self._block_us
            while self._blocks and (sum(b.n for b in self._blocks) - self._blocks[0].n) \
                    * self._dt_us >= keep:
                self._blocks.popleft()
        else:
            self._blocks.clear()
        self._blk_n = 0
        self._blk_sw = [0.0, 0.0, 0.0]
        self._blk_sw2 = [0.0, 0.0, 0.0]
        self._blk_sf = [0.0, 0.0, 0.0]
        self._blk_sf2 = [0.0, 0.0, 0.0]

    def _initialise(self, blocks: deque[_Block] | None) -> None:
        """Aligned: p, q from the pose nearest the horizon, v = 0, b_g = window mean."""
        st = self.settings
        smp = self._pending.popleft()
        self._h_t = smp.t_us
        half = self._dt_us >> 1
        older = [m for m in self._poses if m.capture_us <= self._h_t + half]
        pose = older[-1] if older else self._poses[0]
        self._poses = [m for m in self._poses if m.capture_us > self._h_t + half]
        if blocks:
            n = sum(b.n for b in blocks)
            bg = tuple(sum(b.sw[i] for b in blocks) / n for i in range(3))
            bg_sd = math.hypot(st.gyro_noise_rad_s / math.sqrt(n), 1e-4)
            v_sd = st.init_vel_sd_m_s
        else:
            bg = _ZERO3
            bg_sd = st.init_gyro_bias_sd_rad_s
            v_sd = st.init_vel_sd_in_flight_m_s
        p, q = pose.p_enu_m, pose.q_enu_flu
        self._h_x = (p[0], p[1], p[2], 0.0, 0.0, 0.0, q[0], q[1], q[2], q[3],
                     bg[0], bg[1], bg[2], 0.0, 0.0, 0.0)
        r_p, r_a = self._pose_vars(pose)
        d = [r_p] * 3 + [v_sd ** 2] * 3 + [r_a] * 3 + [bg_sd ** 2] * 3 \
            + [st.init_accel_bias_sd_m_s2 ** 2] * 3
        self._P = np.diag(d)
        self._c_x = self._h_x
        self._c_t = self._h_t
        self._c_dt2 = 0.0
        self._last_capture_us = pose.capture_us
        self._last_pos_fuse_us = self._last_att_fuse_us = pose.capture_us
        self._aligned = True
        self._blocks.clear()
        h_lim = self._last_t - self._delay_us
        pend = self._pending
        self._o_t = -1
        while pend and pend[0].t_us <= h_lim:
            self._predict(pend.popleft())
            self._fuse_due()
        self._repropagate()
        self._resync_t = self._h_t

    # ------------------------------------------------------------------------------------
    # Filter

    def _predict(self, smp: ImuInput) -> None:
        """Horizon state over one sample (Sola eq. 260); covariance every cov_period_s."""
        dt = (smp.t_us - self._h_t) * 1e-6
        self._h_x = _strapdown(self._h_x, smp.omega_flu_rad_s, smp.f_flu_m_s2, dt, self._g)
        self._h_t = smp.t_us
        self._c_dt2 += dt * dt
        if self._h_t - self._c_t >= self._cov_us:
            self._cov_step()

    def _cov_step(self) -> None:
        """P = F P F^T + Q over the samples since the last step (Sola eq. 269-274).

        F from the interval's deltas as EKF2 does on its down-sampled IMU: with
        dV = v1 - v0 - g_W T (world specific-force integral), R [a]x T = [dV]x R, so
        dv/dtheta = -[dV]x R, dv/db_a = -R T, dtheta/dtheta = I - [dtheta_01]x,
        dtheta/db_g = -I T, and the half-interval terms dp/dtheta, dp/db_a, dv/db_g.
        """
        T = (self._h_t - self._c_t) * 1e-6
        if T <= 0.0:
            return
        x0 = self._c_x
        x1 = self._h_x
        # mid-interval attitude (nlerp) and body rotation over the interval
        aw, ax, ay, az = x0[6], x0[7], x0[8], x0[9]
        bw, bx, by, bz = x1[6], x1[7], x1[8], x1[9]
        qw, qx, qy, qz = aw + bw, ax + bx, ay + by, az + bz
        k = 1.0 / math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        qw, qx, qy, qz = qw * k, qx * k, qy * k, qz * k
        # 2 vec(q0* q1): the rotation vector to first order
        ex = 2.0 * (aw * bx - ax * bw - ay * bz + az * by)
        ey = 2.0 * (aw * by + ax * bz - ay * bw - az * bx)
        ez = 2.0 * (aw * bz - ax * by + ay * bx - az * bw)
        dvx = x1[3] - x0[3]
        dvy = x1[4] - x0[4]
        dvz = x1[5] - x0[5] + self._g * T
        xx, yy, zz = qx * qx, qy * qy, qz * qz
        xy, xz, yz = qx * qy, qx * qz, qy * qz
        wx, wy, wz = qw * qx, qw * qy, qw * qz
        r00 = 1.0 - 2.0 * (yy + zz)
        r01 = 2.0 * (xy - wz)
        r02 = 2.0 * (xz + wy)
        r10 = 2.0 * (xy + wz)
        r11 = 1.0 - 2.0 * (xx + zz)
        r12 = 2.0 * (yz - wx)
        r20 = 2.0 * (xz - wy)
        r21 = 2.0 * (yz + wx)
        r22 = 1.0 - 2.0 * (xx + yy)
        # M = [dV]x R, rows: dV x (column j of R) ... row i of [dV]x R
        m00 = -dvz * r10 + dvy * r20
        m01 = -dvz * r11 + dvy * r21
        m02 = -dvz * r12 + dvy * r22
        m10 = dvz * r00 - dvx * r20
        m11 = dvz * r01 - dvx * r21
        m12 = dvz * r02 - dvx * r22
        m20 = -dvy * r00 + dvx * r10
        m21 = -dvy * r01 + dvx * r11
        m22 = -dvy * r02 + dvx * r12
        h = 0.5 * T
        hh = h * T
        self._F_flat[_F_IDX] = (
            T, T, T,
            -h * m00, -h * m01, -h * m02, -h * m10, -h * m11, -h * m12,
            -h * m20, -h * m21, -h * m22,
            -hh * r00, -hh * r01, -hh * r02, -hh * r10, -hh * r11, -hh * r12,
            -hh * r20, -hh * r21, -hh * r22,
            -m00, -m01, -m02, -m10, -m11, -m12, -m20, -m21, -m22,
            h * m00, h * m01, h * m02, h * m10, h * m11, h * m12, h * m20, h * m21, h * m22,
            -T * r00, -T * r01, -T * r02, -T * r10, -T * r11, -T * r12,
            -T * r20, -T * r21, -T * r22,
            1.0, ez, -ey, -ez, 1.0, ex, ey, -ex, 1.0,
            -T, -T, -T)
        st = self.settings
        qa = st.accel_noise_m_s2 ** 2 * self._c_dt2
        qg = st.gyro_noise_rad_s ** 2 * self._c_dt2
        qbg = st.gyro_bias_noise_rad_s2 ** 2 * T
        qba = st.accel_bias_noise_m_s3 ** 2 * T
        F = self._F
        P = F.dot(self._P).dot(F.T)
        P.flat[::16] += (0.0, 0.0, 0.0, qa, qa, qa, qg, qg, qg, qbg, qbg, qbg, qba, qba, qba)
        self._n_pred += 1
        if self._n_pred & 7 == 0:
            P += P.T
            P *= 0.5
            self._bound(P)
        self._P = P
        self._c_x = x1
        self._c_t = self._h_t
        self._c_dt2 = 0.0

    def _bound(self, P: np.ndarray) -> None:
        """Diagonal floors and the var_max clamp (row/column scaling keeps P SPD)."""
        d = P.diagonal()
        if (d < self._var_min).any():
            P.flat[::16] = np.maximum(d, self._var_min)
        vmax = self.settings.var_max
        if (d > vmax).any():
            k = np.sqrt(np.minimum(1.0, vmax / np.maximum(d, 1e-300)))
            P *= k[:, None]
            P *= k[None, :]

    def _pose_vars(self, m: PoseInput) -> tuple[float, float]:
        r_p = m.pos_var_m2 if m.pos_var_m2 > self._r_pos_floor else self._r_pos_floor
        r_a = m.att_var_rad2 if m.att_var_rad2 > self._r_att_floor else self._r_att_floor
        return r_p, r_a  # NaN compares False: the floor

    def _fuse_due(self) -> None:
        half = self._dt_us >> 1
        while self._poses and self._poses[0].capture_us <= self._h_t + half:
            m = self._poses.pop(0)
            if m.capture_us <= self._last_capture_us:
                self._pose_ignored += 1
                continue
            self._fuse(m)

    def _fuse(self, m: PoseInput) -> None:
        """Gate position and attitude separately, Joseph update, inject, reset (Sola 6)."""
        self._last_capture_us = m.capture_us
        self._cov_step()
        x = self._h_x
        q_hat: Quat = (x[6], x[7], x[8], x[9])
        zp = m.p_enu_m
        yp: Vec3 = (zp[0] - x[0], zp[1] - x[1], zp[2] - x[2])
        ya = q_log(q_mul(q_conj(q_hat), m.q_enu_flu))
        r_p, r_a = self._pose_vars(m)
        P = self._P
        d = P.diagonal().tolist()
        g2 = self._gate2
        tr_p = max(yp[i] * yp[i] / (g2 * (d[i] + r_p)) for i in range(3))
        tr_a = max(ya[i] * ya[i] / (g2 * (d[6 + i] + r_a)) for i in range(3))
        self._pos_innov, self._att_innov = yp, ya
        self._pos_ratio, self._att_ratio = tr_p, tr_a
        ok_p, ok_a = tr_p <= 1.0, tr_a <= 1.0
        if ok_p and ok_a:
            self._update(_H_BOTH, [*yp, *ya], [r_p] * 3 + [r_a] * 3)
        elif ok_p:
            self._update(_H_POS, list(yp), [r_p] * 3)
        elif ok_a:
            self._update(_H_ATT, list(ya), [r_a] * 3)
        c = m.capture_us
        reset = False
        if ok_p:
            self._last_pos_fuse_us = c
        if ok_a:
            self._last_att_fuse_us = c
        if ok_p or ok_a:
            self._last_fusion_us = c
        if ok_p and ok_a:
            self._fused += 1
            self._rejected_in_row = 0
        else:
            self._rejected += 1
            self._rejected_in_row += 1
            if not ok_p and c - self._last_pos_fuse_us > self._timeout_us:
                self._reset_block(0, zp, r_p)
                self._last_pos_fuse_us = c
                reset = True
            if not ok_a and c - self._last_att_fuse_us > self._timeout_us:
                self._reset_block(6, m.q_enu_flu, r_a)
                self._last_att_fuse_us = c
                reset = True
        if ok_p or ok_a or reset:
            self._correct_output(x, reset)

    def _reset_block(self, i0: int, z: tuple[float, ...], r: float) -> None:
        """EKF2-style reset to the pose: the state part set, its covariance rows cleared."""
        x = list(self._h_x)
        if i0 == 0:
            x[0:3] = z[0:3]
        else:
            x[6:10] = z[0:4]
        self._h_x = (x[0], x[1], x[2], x[3], x[4], x[5], x[6], x[7], x[8], x[9], x[10],
                     x[11], x[12], x[13], x[14], x[15])
        P = self._P
        P[i0:i0 + 3, :] = 0.0
        P[:, i0:i0 + 3] = 0.0
        P[i0:i0 + 3, i0:i0 + 3] = np.eye(3) * r
        self._resets += 1
        self._rejected_in_row = 0

    def _update(self, H: np.ndarray, y: list[float], r: list[float]) -> None:
        """Joseph-form update with the selector H (rows of I15), symmetrised; injection
        (Sola eq. 282-283) and the attitude reset G = I - [dtheta/2]x (eq. 287) folded in:
        P = (G A) P (G A)^T + (G K) R (G K)^T, A = I - K H."""
        P = self._P
        pht = P.dot(H.T)
        S = H.dot(pht)
        S.flat[::len(r) + 1] += r
        K = pht.dot(np.linalg.inv(S))
        dx = K.dot(y).tolist()
        hx, hy, hz = 0.5 * dx[6], 0.5 * dx[7], 0.5 * dx[8]
        Gr = _I15.copy()
        Gr.flat[_G_IDX] = (hz, -hy, -hz, hx, hy, -hx)
        A = Gr.dot(_I15 - K.dot(H))
        GK = Gr.dot(K)
        P = A.dot(P).dot(A.T)
        P += (GK * r).dot(GK.T)
        P += P.T
        P *= 0.5
        x = self._h_x
        q = q_mul((x[6], x[7], x[8], x[9]), q_exp((dx[6], dx[7], dx[8])))
        n = 1.0 / math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
        self._h_x = (x[0] + dx[0], x[1] + dx[1], x[2] + dx[2],
                     x[3] + dx[3], x[4] + dx[4], x[5] + dx[5],
                     q[0] * n, q[1] * n, q[2] * n, q[3] * n,
                     x[10] + dx[9], x[11] + dx[10], x[12] + dx[11],
                     x[13] + dx[12], x[14] + dx[13], x[15] + dx[14])
        self._bound(P)
        self._P = P

    def _correct_output(self, xb: _State, exact: bool) -> None:
        """Carry the horizon's correction (xb -> x) to the output state.

        Linearised over the buffered interval T: dp += T dv - T/2 dV x dth_W - T^2/2 R db_a,
        dv += -dV x dth_W - T R db_a + T/2 dV x R db_g, q_o = q_h (q_hb* q_o) exp(-T db_g),
        dV the interval's world specific-force integral; exact re-propagation after a
        reset, with output_repropagate, and every output_resync_s.
        """
        if self._o_t < self._h_t:
            return
        if (exact or self._o_t == self._h_t or self.settings.output_repropagate
                or self._h_t - self._resync_t >= self._resync_us):
            self._repropagate()
            self._resync_t = self._h_t
            return
        xa = self._h_x
        xo = self._o_x
        T = (self._o_t - self._h_t) * 1e-6
        qb: Quat = (xb[6], xb[7], xb[8], xb[9])
        qa: Quat = (xa[6], xa[7], xa[8], xa[9])
        e = q_mul(qa, q_conj(qb))  # world-frame correction rotation
        sg = 2.0 if e[0] >= 0.0 else -2.0
        thx, thy, thz = sg * e[1], sg * e[2], sg * e[3]
        dvx = xo[3] - xb[3]
        dvy = xo[4] - xb[4]
        dvz = xo[5] - xb[5] + self._g * T
        ba = q_rotate(qb, (xa[13] - xb[13], xa[14] - xb[14], xa[15] - xb[15]))
        dbg = (xa[10] - xb[10], xa[11] - xb[11], xa[12] - xb[12])
        bg = q_rotate(qb, dbg)
        # c = dV x dth_W, d = dV x R db_g
        cx = dvy * thz - dvz * thy
        cy = dvz * thx - dvx * thz
        cz = dvx * thy - dvy * thx
        ex = dvy * bg[2] - dvz * bg[1]
        ey = dvz * bg[0] - dvx * bg[2]
        ez = dvx * bg[1] - dvy * bg[0]
        h = 0.5 * T
        ux = xa[3] - xb[3]
        uy = xa[4] - xb[4]
        uz = xa[5] - xb[5]
        q = q_mul(q_mul(qa, q_mul(q_conj(qb), (xo[6], xo[7], xo[8], xo[9]))),
                  q_exp((-T * dbg[0], -T * dbg[1], -T * dbg[2])))
        k = 1.0 / math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
        self._o_x = (xo[0] + xa[0] - xb[0] + T * ux - h * cx - h * T * ba[0],
                     xo[1] + xa[1] - xb[1] + T * uy - h * cy - h * T * ba[1],
                     xo[2] + xa[2] - xb[2] + T * uz - h * cz - h * T * ba[2],
                     xo[3] + ux - cx - T * ba[0] + h * ex,
                     xo[4] + uy - cy - T * ba[1] + h * ey,
                     xo[5] + uz - cz - T * ba[2] + h * ez,
                     q[0] * k, q[1] * k, q[2] * k, q[3] * k,
                     xa[10], xa[11], xa[12], xa[13], xa[14], xa[15])

    def _repropagate(self) -> None:
        """Output = horizon state propagated over the buffered samples (output predictor)."""
        x = self._h_x
        t = self._h_t
        g = self._g
        for s in self._pending:
            x = _strapdown(x, s.omega_flu_rad_s, s.f_flu_m_s2, (s.t_us - t) * 1e-6, g)
            t = s.t_us
        self._o_x = x
        self._o_t = t

    # ------------------------------------------------------------------------------------
    # Outputs

    def output(self) -> tuple[int, VehicleState] | None:
        """(t_us, state at the newest IMU sample), None before aligned."""
        if not self._aligned:
            return None
        x = self._o_x
        q: Quat = (x[6], x[7], x[8], x[9])
        w = self._last_w
        return self._o_t, VehicleState((x[0], x[1], x[2]), q,
                                       q_rotate_inv(q, (x[3], x[4], x[5])),
                                       (w[0] - x[10], w[1] - x[11], w[2] - x[12]))

    def health(self) -> EstimatorHealth:
        """What the failsafes and arming need each control period, without status()'s
        Cholesky test (the covariance is kept positive definite by construction; status()
        checks it for telemetry and logs): finite state, the standard deviations."""
        st = self.settings
        if not self._aligned:
            return EstimatorHealth(False, False, False, self._rejected_in_row,
                                   self._last_fusion_us)
        d = self._P.diagonal().tolist()
        if not (math.isfinite(sum(d)) and math.isfinite(sum(self._o_x)) and min(d) > 0.0):
            return EstimatorHealth(True, False, False, self._rejected_in_row,
                                   self._last_fusion_us)
        pos_var, vel_var, att_var = max(d[0:3]), max(d[3:6]), max(d[6:9])
        healthy = (pos_var < st.healthy_pos_sd_max_m ** 2
                   and vel_var < st.healthy_vel_sd_max_m_s ** 2
                   and att_var < st.healthy_att_sd_max_rad ** 2)
        converged = (healthy and pos_var < st.converged_pos_sd_m ** 2
                     and vel_var < st.converged_vel_sd_m_s ** 2
                     and att_var < st.converged_att_sd_rad ** 2)
        return EstimatorHealth(True, converged, healthy, self._rejected_in_row,
                               self._last_fusion_us)

    def status(self) -> EstimatorStatus:
        st = self.settings
        x = self._o_x
        if self._aligned:
            P = self._P
            d = P.diagonal()
            finite = bool(np.isfinite(P).all()) and all(math.isfinite(v) for v in x)
            sd = np.sqrt(np.maximum(d, 0.0)).tolist() if finite else [math.inf] * _N
            spd = finite
            if finite:
                try:
                    np.linalg.cholesky(0.5 * (P + P.T))
                except np.linalg.LinAlgError:
                    spd = False
        else:
            sd = [math.nan] * _N
            spd = False

        def v3(i: int) -> Vec3:
            return (sd[i], sd[i + 1], sd[i + 2])

        pos_sd, vel_sd, att_sd = max(sd[0:3]), max(sd[3:6]), max(sd[6:9])
        healthy = (spd and pos_sd < st.healthy_pos_sd_max_m
                   and vel_sd < st.healthy_vel_sd_max_m_s and att_sd < st.healthy_att_sd_max_rad)
        converged = (healthy and pos_sd < st.converged_pos_sd_m
                     and vel_sd < st.converged_vel_sd_m_s and att_sd < st.converged_att_sd_rad)
        return EstimatorStatus(
            t_us=self._o_t if self._aligned else self._last_t,
            aligned=self._aligned, converged=converged,
            pos_sd_m=v3(0), vel_sd_m_s=v3(3), att_sd_rad=v3(6), gyro_bias_sd=v3(9),
            accel_bias_sd=v3(12),
            gyro_bias_rad_s=(x[10], x[11], x[12]), accel_bias_m_s2=(x[13], x[14], x[15]),
            pos_innov_m=self._pos_innov, att_innov_rad=self._att_innov,
            pos_test_ratio=self._pos_ratio, att_test_ratio=self._att_ratio,
            rejected_in_row=self._rejected_in_row, last_fusion_us=self._last_fusion_us,
            fused=self._fused, rejected=self._rejected, healthy=healthy,
            imu_ignored=self._imu_ignored, pose_ignored=self._pose_ignored,
            resets=self._resets)
