"""The filter: inputs in arrival order, the delayed horizon, fusion and outputs.

The design is described in `fcu.estimator` (the package docstring). Before it is aligned the
filter is Python (the stationary window, `fcu.estimator.align`); once aligned its state
lives in flat buffers (`fcu.estimator.layouts` EF_*, EI_*) that compiled kernels advance
(`fcu.estimator.filter`): an IMU sample is one kernel call, a pose fusion one.
"""

from __future__ import annotations

import bisect
import math
from collections import deque

import numpy as np

from common.jit import compiled_for
from common.quaternion import Vec3
from common.warm_ups import warm_up
from fcu.estimator.align import AlignWindow
from fcu.estimator.buffers import filter_buffers
from fcu.estimator.filter import (
    DONE,
    FUSE,
    GROW,
    OUTPUT,
    PUSH,
    cov_step,
    fuse,
    imu_step,
    pose_step,
    repropagate,
)
from fcu.estimator.inputs import ImuInput, PoseInput
from fcu.estimator.layouts import (
    EF_C_DT2,
    EF_C_X,
    EF_H_X,
    EF_INNOV,
    EF_LAST_W,
    EF_O_X,
    EF_RATIO,
    EF_SD,
    EI_C_T,
    EI_FUSED,
    EI_H_T,
    EI_LAST_ATT_FUSE,
    EI_LAST_CAPTURE,
    EI_LAST_FUSION,
    EI_LAST_POS_FUSE,
    EI_O_T,
    EI_PEND_HEAD,
    EI_PEND_N,
    EI_POSE_IGNORED,
    EI_POSES_N,
    EI_REJ_ROW,
    EI_REJECTED,
    EI_RESETS,
    EI_RESYNC_T,
)
from fcu.estimator.readout import output_values, positive_definite, sd_values, variance_code
from fcu.estimator.settings import EstimatorSettings
from fcu.estimator.status import EstimatorHealth, EstimatorStatus, sd_verdict
from fcu.estimator.strapdown import N, State
from fcu.stages import VehicleState

_ZERO3: Vec3 = (0.0, 0.0, 0.0)
_DEFAULTS = EstimatorSettings()
_T_MAX = 1 << 62  # larger times (us) are refused: the kernels' integers are 64-bit


class Estimator:
    """The filter; feed on_imu and on_pose in arrival order, read output() and status()."""

    def __init__(self, settings: EstimatorSettings = _DEFAULTS) -> None:
        self.settings = settings
        s = settings
        self._g = s.gravity_m_s2
        self._delay_us = round(s.pose_delay_s * 1e6)
        self._align_us = round(s.align_time_s * 1e6)
        warm()
        self.reset()
        # the hot kernels' machine code for the buffers' types (`compiled_for`): `reset`
        # makes new buffers of the same types
        fb, ib, M, pend_t, pend_v, pose_c, pose_v = (self._fb, self._ib, self._M, self._pend_t,
                                                     self._pend_v, self._pose_c, self._pose_v)
        self._imu_step = compiled_for(imu_step, fb, ib, M, pend_t, pend_v, pose_c, pose_v, 0,
                                      0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0, 0)
        self._fuse = compiled_for(fuse, fb, ib, M, pend_t, pend_v)
        self._pose_step = compiled_for(pose_step, fb, ib, pose_c, pose_v, 0, np.zeros(9), 0)
        self._variance_code = compiled_for(variance_code, fb, M)

    # ------------------------------------------------------------------------------------
    # State

    def reset(self) -> None:
        """Back to unaligned: every state, buffer and counter cleared."""
        s = self.settings
        self._aligned = False
        self._last_t = -1
        self._last_w: Vec3 = _ZERO3
        self._dt_us = 1000  # nominal IMU period (the shortest interval seen)
        self._dt_seen = False
        self._pending: deque[ImuInput] = deque()  # samples newer than the horizon (unaligned)
        self._poses: list[PoseInput] = []  # queued, by capture time (unaligned)
        self._latest_pose: PoseInput | None = None
        self._window = AlignWindow(s)
        self._imu_ignored = 0
        (self._fb, self._ib, self._M, self._pend_t, self._pend_v, self._pose_c,
         self._pose_v) = filter_buffers(s)

    @property
    def aligned(self) -> bool:
        return self._aligned

    @property
    def covariance(self) -> np.ndarray:
        """A copy of the 15x15 error-state covariance at the horizon."""
        P: np.ndarray = self._M[0]
        return P.copy()

    # The filter's state as the interpreted filter kept it (tests read and set these).

    @property
    def _P(self) -> np.ndarray:
        P: np.ndarray = self._M[0]
        return P

    @_P.setter
    def _P(self, P: np.ndarray) -> None:
        self._M[0] = P

    @property
    def _F(self) -> np.ndarray:
        F: np.ndarray = self._M[1]
        return F

    def _state(self, i: int) -> State:
        x = self._fb[i:i + 16].tolist()
        return (x[0], x[1], x[2], x[3], x[4], x[5], x[6], x[7], x[8], x[9], x[10], x[11],
                x[12], x[13], x[14], x[15])

    @property
    def _h_x(self) -> State:
        return self._state(EF_H_X)

    @_h_x.setter
    def _h_x(self, x: State) -> None:
        self._fb[EF_H_X:EF_H_X + 16] = x

    @property
    def _c_x(self) -> State:
        return self._state(EF_C_X)

    @_c_x.setter
    def _c_x(self, x: State) -> None:
        self._fb[EF_C_X:EF_C_X + 16] = x

    @property
    def _o_x(self) -> State:
        return self._state(EF_O_X)

    @property
    def _h_t(self) -> int:
        return int(self._ib[EI_H_T])

    @_h_t.setter
    def _h_t(self, t: int) -> None:
        self._ib[EI_H_T] = t

    @property
    def _c_t(self) -> int:
        return int(self._ib[EI_C_T])

    @_c_t.setter
    def _c_t(self, t: int) -> None:
        self._ib[EI_C_T] = t

    @property
    def _c_dt2(self) -> float:
        return float(self._fb[EF_C_DT2])

    @_c_dt2.setter
    def _c_dt2(self, v: float) -> None:
        self._fb[EF_C_DT2] = v

    def _cov_step(self) -> None:
        """P = F P F^T + Q over the samples since the last step (`filter.cov_step`)."""
        cov_step(self._fb, self._ib, self._M)

    # ------------------------------------------------------------------------------------
    # Inputs

    def on_imu(self, s: ImuInput) -> None:
        """One IMU sample: buffer it, advance the horizon, propagate the output to s.t_us."""
        w = s.omega_flu_rad_s
        f = s.f_flu_m_s2
        try:
            t = s.t_us if type(s.t_us) is int else int(s.t_us)
            ok = math.isfinite(w[0] + w[1] + w[2] + f[0] + f[1] + f[2]) and \
                self._last_t < t < _T_MAX
        except (TypeError, IndexError, OverflowError, ValueError):
            ok = False
        if not ok:
            self._imu_ignored += 1
            return
        if self._last_t >= 0:  # the nominal period: the shortest interval (a gap is no period)
            dt = t - self._last_t
            if dt < self._dt_us or not self._dt_seen:
                self._dt_us = dt
            self._dt_seen = True
        self._last_t = t
        self._last_w = w
        if self._aligned:
            code = self._imu_step(self._fb, self._ib, self._M, self._pend_t, self._pend_v,
                                  self._pose_c, self._pose_v, t, w[0], w[1], w[2], f[0], f[1],
                                  f[2], self._dt_us, PUSH | OUTPUT)
            if code != DONE:
                self._advance(t, w, f, PUSH | OUTPUT, code)
            return
        if t is not s.t_us:
            s = s._replace(t_us=t)
        self._pending.append(s)
        self._align_step(s)

    def _advance(self, t: int, w: Vec3, f: Vec3, mode: int, code: int = -1) -> None:
        """`filter.imu_step` until done (code: what it answered last, -1 not called yet):
        the ring grown when full (GROW), each due pose fused (FUSE)."""
        while True:
            if code == DONE:
                return
            if code == GROW:
                self._grow(2 * len(self._pend_t))
            elif code == FUSE:
                self._fuse_current()
                mode &= ~PUSH
            code = self._imu_step(self._fb, self._ib, self._M, self._pend_t, self._pend_v,
                                  self._pose_c, self._pose_v, t, w[0], w[1], w[2], f[0], f[1],
                                  f[2], self._dt_us, mode)

    def _grow(self, cap: int) -> None:
        """The ring of buffered samples at capacity cap, oldest first."""
        ib = self._ib
        n, head, old = int(ib[EI_PEND_N]), int(ib[EI_PEND_HEAD]), len(self._pend_t)
        idx = (head + np.arange(n)) % old
        pend_t = np.zeros(cap, dtype=np.int64)
        pend_v = np.zeros((cap, 6))
        pend_t[:n] = self._pend_t[idx]
        pend_v[:n] = self._pend_v[idx]
        self._pend_t, self._pend_v = pend_t, pend_v
        ib[EI_PEND_HEAD] = 0

    def on_pose(self, m: PoseInput) -> None:
        """Queue a pose; it is fused when the horizon reaches capture_us (in time order)."""
        checked = self._check_pose(m)
        if checked is None:
            self._ib[EI_POSE_IGNORED] += 1
            return
        m = checked
        half = self._dt_us >> 1
        c = m.capture_us
        if self._last_t < 0 or c > self._last_t + half:  # no IMU yet, or in the future
            self._ib[EI_POSE_IGNORED] += 1
            return
        if not self._aligned:
            if self._latest_pose is None or c > self._latest_pose.capture_us:
                self._latest_pose = m
            self._queue(m)
            return
        if c < -_T_MAX:  # behind the horizon
            self._ib[EI_POSE_IGNORED] += 1
            return
        v = np.array((*m.p_enu_m, *m.q_enu_flu, m.pos_var_m2, m.att_var_rad2))
        if self._pose_step(self._fb, self._ib, self._pose_c, self._pose_v, c, v,
                           self._dt_us) == FUSE:
            self._fuse_current()

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
            self._ib[EI_POSE_IGNORED] += 1

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
        """Aligned: p, q from the pose nearest the horizon, v = 0, b_g = window mean; the
        buffered samples and queued poses move into the kernels' buffers, the horizon
        advances over them."""
        st = self.settings
        smp = self._pending.popleft()
        h_t = smp.t_us
        half = self._dt_us >> 1
        older = [m for m in self._poses if m.capture_us <= h_t + half]
        pose = older[-1] if older else self._poses[0]
        poses = [m for m in self._poses if m.capture_us > h_t + half]
        self._poses = []
        if ground:
            bg, bg_sd = self._window.gyro_bias()
            v_sd = st.init_vel_sd_m_s
        else:
            bg = _ZERO3
            bg_sd = st.init_gyro_bias_sd_rad_s
            v_sd = st.init_vel_sd_in_flight_m_s
        p, q = pose.p_enu_m, pose.q_enu_flu
        x = (p[0], p[1], p[2], 0.0, 0.0, 0.0, q[0], q[1], q[2], q[3],
             bg[0], bg[1], bg[2], 0.0, 0.0, 0.0)
        r_p, r_a = self._pose_vars(pose)
        d = [r_p] * 3 + [v_sd ** 2] * 3 + [r_a] * 3 + [bg_sd ** 2] * 3 \
            + [st.init_accel_bias_sd_m_s2 ** 2] * 3
        fb, ib = self._fb, self._ib
        fb[EF_H_X:EF_H_X + 16] = x
        fb[EF_C_X:EF_C_X + 16] = x
        fb[EF_C_DT2] = 0.0
        fb[EF_LAST_W:EF_LAST_W + 3] = self._last_w
        self._M[0] = np.diag(d)
        ib[EI_H_T] = ib[EI_C_T] = h_t
        ib[EI_LAST_CAPTURE] = pose.capture_us
        ib[EI_LAST_POS_FUSE] = ib[EI_LAST_ATT_FUSE] = pose.capture_us
        self._aligned = True
        self._window.blocks.clear()
        pend = self._pending
        cap = len(self._pend_t)
        while cap < len(pend):
            cap *= 2
        self._grow(cap)
        for k, smp in enumerate(pend):
            self._pend_t[k] = smp.t_us
            self._pend_v[k] = (*smp.omega_flu_rad_s, *smp.f_flu_m_s2)
        ib[EI_PEND_HEAD], ib[EI_PEND_N] = 0, len(pend)
        pend.clear()
        for k, m in enumerate(poses):
            self._pose_c[k] = m.capture_us
            self._pose_v[k] = (*m.p_enu_m, *m.q_enu_flu, m.pos_var_m2, m.att_var_rad2)
        ib[EI_POSES_N] = len(poses)
        ib[EI_O_T] = -1
        self._advance(self._last_t, self._last_w, self._last_w, 0)
        repropagate(fb, ib, self._pend_t, self._pend_v)
        ib[EI_RESYNC_T] = ib[EI_H_T]

    # ------------------------------------------------------------------------------------
    # Filter

    def _pose_vars(self, m: PoseInput) -> tuple[float, float]:
        r_pos_floor = self.settings.pose_pos_noise_m ** 2
        r_att_floor = self.settings.pose_att_noise_rad ** 2
        r_p = m.pos_var_m2 if m.pos_var_m2 > r_pos_floor else r_pos_floor
        r_a = m.att_var_rad2 if m.att_var_rad2 > r_att_floor else r_att_floor
        return r_p, r_a  # NaN compares False: the floor

    def _fuse_current(self) -> None:
        """The pose under way: gated, fused, counted, one compiled call (`filter.fuse`)."""
        self._fuse(self._fb, self._ib, self._M, self._pend_t, self._pend_v)

    # ------------------------------------------------------------------------------------
    # Outputs

    def output(self) -> tuple[int, VehicleState] | None:
        """(t_us, state at the newest IMU sample), None before aligned."""
        if not self._aligned:
            return None
        t, p, q, v, w = output_values(self._fb, self._ib)
        return t, VehicleState(p, q, v, w)

    def output_arrays(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The arrays `readout.output_values` reads (fb, ib), for a caller's compiled
        readout of the output state; None before aligned."""
        return (self._fb, self._ib) if self._aligned else None

    def health(self) -> EstimatorHealth:
        """What the failsafes and arming need each control period, without status()'s
        Cholesky test (the covariance is kept positive definite by construction; status()
        checks it for telemetry and logs): finite state, the standard deviations."""
        ib = self._ib
        code = self._variance_code(self._fb, self._M) if self._aligned else 0
        return EstimatorHealth(self._aligned, code == 3, code != 0, int(ib[EI_REJ_ROW]),
                               int(ib[EI_LAST_FUSION]))

    def status(self) -> EstimatorStatus:
        fb = self._fb
        if self._aligned:
            finite = sd_values(fb, self._M)
            sd = fb[EF_SD:EF_SD + N].tolist()
            spd = finite and positive_definite(self._M)
        else:
            sd = [math.nan] * N
            spd = False
        converged, healthy = sd_verdict(self.settings, sd, spd)
        x = fb[EF_O_X:EF_O_X + 16].tolist()
        e = fb[EF_INNOV:EF_INNOV + 6].tolist()
        tr_p, tr_a = fb[EF_RATIO:EF_RATIO + 2].tolist()
        iv = self._ib.tolist()

        def v3(a: list[float], i: int) -> Vec3:
            return (a[i], a[i + 1], a[i + 2])

        return EstimatorStatus(
            t_us=iv[EI_O_T] if self._aligned else self._last_t,
            aligned=self._aligned, converged=converged,
            pos_sd_m=v3(sd, 0), vel_sd_m_s=v3(sd, 3), att_sd_rad=v3(sd, 6),
            gyro_bias_sd=v3(sd, 9), accel_bias_sd=v3(sd, 12),
            gyro_bias_rad_s=v3(x, 10), accel_bias_m_s2=v3(x, 13),
            pos_innov_m=v3(e, 0), att_innov_rad=v3(e, 3),
            pos_test_ratio=tr_p, att_test_ratio=tr_a,
            rejected_in_row=iv[EI_REJ_ROW], last_fusion_us=iv[EI_LAST_FUSION],
            fused=iv[EI_FUSED], rejected=iv[EI_REJECTED], healthy=healthy,
            imu_ignored=self._imu_ignored, pose_ignored=iv[EI_POSE_IGNORED],
            resets=iv[EI_RESETS])


def _warm_up() -> None:
    """Every kernel once on inputs of their run-time types (compiled, or loaded from the
    cache): an in-flight alignment, fusions, a rejection and a reset, the outputs."""
    est = Estimator(EstimatorSettings(align_in_flight=True, pose_reset_timeout_s=0.005))
    for k in range(1, 40):
        est.on_imu(ImuInput(k * 1000, (0.0, 0.0, 0.0), (0.0, 0.0, 9.81)))
        p = (0.0, 0.0, 0.0) if k < 30 else (1.0, 0.0, 0.0)
        est.on_pose(PoseInput(k * 1000 - 25_000, p, (1.0, 0.0, 0.0, 0.0)))
        est.on_pose(PoseInput(k * 1000 - 15_000, p, (1.0, 0.0, 0.0, 0.0)))
    est.output()
    est.health()
    est.status()


def warm() -> None:
    """Load (or compile, on a fresh cache) the estimator's kernels once per process: every
    Estimator made does; the FCU calls it as it starts in real time, so that an Estimator
    made later, when EKF_EN turns it on over the link, starts at once."""
    warm_up("fcu.estimator", _warm_up)
