"""The filter: inputs in arrival order, the delayed horizon, fusion and outputs.

The design is described in `fcu.estimator` (the package docstring).
"""

from __future__ import annotations

import bisect
import math
from collections import deque

import numpy as np

from common.quaternion import Quat, Vec3, q_conj, q_log, q_mul, q_rotate_inv
from fcu.estimator.align import AlignWindow
from fcu.estimator.inputs import ImuInput, PoseInput
from fcu.estimator.output import corrected_output, propagate
from fcu.estimator.settings import EstimatorSettings
from fcu.estimator.status import EstimatorHealth, EstimatorStatus, sd_verdict, variance_verdict
from fcu.estimator.strapdown import F_IDX, N, State, strapdown, transition_entries
from fcu.estimator.update import (
    H_ATT,
    H_BOTH,
    H_POS,
    bound_covariance,
    inject,
    joseph_update,
    reset_block,
)
from fcu.tracker import VehicleState

_ZERO3: Vec3 = (0.0, 0.0, 0.0)
_DEFAULTS = EstimatorSettings()


class Estimator:
    """The filter; feed on_imu and on_pose in arrival order, read output() and status()."""

    def __init__(self, settings: EstimatorSettings = _DEFAULTS) -> None:
        self.settings = settings
        s = settings
        self._g = s.gravity_m_s2
        self._delay_us = round(s.pose_delay_s * 1e6)
        self._gate2 = s.pose_gate_sd * s.pose_gate_sd
        self._r_pos_floor = s.pose_pos_noise_m ** 2
        self._r_att_floor = s.pose_att_noise_rad ** 2
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
        self._window = AlignWindow(self.settings)
        # horizon (filter) and output states
        zero16 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                  0.0)
        self._h_x: State = zero16
        self._h_t = -1
        self._o_x: State = zero16
        self._o_t = -1
        self._P = np.zeros((N, N))
        self._F = np.eye(N)
        self._F_flat = self._F.reshape(-1)
        self._n_pred = 0
        self._c_x: State = zero16  # horizon state at the last covariance step
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
            self._o_x = strapdown(self._o_x, w, f, (t - self._o_t) * 1e-6, self._g)
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
                self._initialise(ground=False)
            return
        self._window.add(s, self._dt_us)
        if self._latest_pose is None or pend[0].t_us > h_lim:
            return
        dur = self._window.duration_us(self._dt_us)
        if dur >= self._align_us and dur > 0:
            age = s.t_us - self._latest_pose.capture_us
            if age <= self.settings.align_pose_max_age_s * 1e6:
                self._initialise(ground=True)

    def _initialise(self, ground: bool) -> None:
        """Aligned: p, q from the pose nearest the horizon, v = 0, b_g = window mean."""
        st = self.settings
        smp = self._pending.popleft()
        self._h_t = smp.t_us
        half = self._dt_us >> 1
        older = [m for m in self._poses if m.capture_us <= self._h_t + half]
        pose = older[-1] if older else self._poses[0]
        self._poses = [m for m in self._poses if m.capture_us > self._h_t + half]
        if ground:
            bg, bg_sd = self._window.gyro_bias()
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
        self._window.blocks.clear()
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
        self._h_x = strapdown(self._h_x, smp.omega_flu_rad_s, smp.f_flu_m_s2, dt, self._g)
        self._h_t = smp.t_us
        self._c_dt2 += dt * dt
        if self._h_t - self._c_t >= self._cov_us:
            self._cov_step()

    def _cov_step(self) -> None:
        """P = F P F^T + Q over the samples since the last step (Sola eq. 269-274).

        F's entries from `transition_entries`; per-sample IMU noise summed over the
        interval's dt^2, bias random walks over T.
        """
        T = (self._h_t - self._c_t) * 1e-6
        if T <= 0.0:
            return
        self._F_flat[F_IDX] = transition_entries(self._c_x, self._h_x, T, self._g)
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
            bound_covariance(P, self._var_min, self.settings.var_max)
        self._P = P
        self._c_x = self._h_x
        self._c_t = self._h_t
        self._c_dt2 = 0.0

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
            self._update(H_BOTH, [*yp, *ya], [r_p] * 3 + [r_a] * 3)
        elif ok_p:
            self._update(H_POS, list(yp), [r_p] * 3)
        elif ok_a:
            self._update(H_ATT, list(ya), [r_a] * 3)
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
        """Reset the position (i0 = 0) or attitude (i0 = 6) to the pose (`reset_block`)."""
        self._h_x = reset_block(self._h_x, self._P, i0, z, r)
        self._resets += 1
        self._rejected_in_row = 0

    def _update(self, H: np.ndarray, y: list[float], r: list[float]) -> None:
        """Joseph update, injection and reset (Sola eq. 282-287), then the bounds."""
        P, dx = joseph_update(self._P, H, y, r)
        self._h_x = inject(self._h_x, dx)
        bound_covariance(P, self._var_min, self.settings.var_max)
        self._P = P

    def _correct_output(self, xb: State, exact: bool) -> None:
        """Carry the horizon's correction (xb -> x) to the output state.

        Linearised over the buffered interval (`corrected_output`); exact re-propagation
        after a reset, with output_repropagate, and every output_resync_s.
        """
        if self._o_t < self._h_t:
            return
        if (exact or self._o_t == self._h_t or self.settings.output_repropagate
                or self._h_t - self._resync_t >= self._resync_us):
            self._repropagate()
            self._resync_t = self._h_t
            return
        self._o_x = corrected_output(xb, self._h_x, self._o_x,
                                     (self._o_t - self._h_t) * 1e-6, self._g)

    def _repropagate(self) -> None:
        """Output = horizon state propagated over the buffered samples (output predictor)."""
        self._o_x, self._o_t = propagate(self._h_x, self._h_t, self._pending, self._g)

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
        converged, healthy = variance_verdict(self.settings, self._P, self._o_x,
                                              self._aligned)
        return EstimatorHealth(self._aligned, converged, healthy, self._rejected_in_row,
                               self._last_fusion_us)

    def status(self) -> EstimatorStatus:
        x = self._o_x
        sd, converged, healthy = sd_verdict(self.settings, self._P, x, self._aligned)

        def v3(i: int) -> Vec3:
            return (sd[i], sd[i + 1], sd[i + 2])

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
