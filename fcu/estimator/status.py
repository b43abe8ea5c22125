"""What the estimator reports: the flight checks' health and the full status."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from common.quaternion import Vec3
from fcu.estimator.settings import EstimatorSettings
from fcu.estimator.strapdown import N, State


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



def variance_verdict(st: EstimatorSettings, P: np.ndarray, x: State, aligned: bool
                     ) -> tuple[bool, bool]:
    """(converged, healthy) from the largest variances of position, velocity and attitude
    (no Cholesky test: `health`'s cheap check each control period)."""
    if not aligned:
        return False, False
    d = P.diagonal().tolist()
    if not (math.isfinite(sum(d)) and math.isfinite(sum(x)) and min(d) > 0.0):
        return False, False
    pos_var, vel_var, att_var = max(d[0:3]), max(d[3:6]), max(d[6:9])
    healthy = (pos_var < st.healthy_pos_sd_max_m ** 2
               and vel_var < st.healthy_vel_sd_max_m_s ** 2
               and att_var < st.healthy_att_sd_max_rad ** 2)
    converged = (healthy and pos_var < st.converged_pos_sd_m ** 2
                 and vel_var < st.converged_vel_sd_m_s ** 2
                 and att_var < st.converged_att_sd_rad ** 2)
    return converged, healthy


def sd_verdict(st: EstimatorSettings, P: np.ndarray, x: State, aligned: bool
               ) -> tuple[list[float], bool, bool]:
    """(the 15 standard deviations, converged, healthy): healthy needs a finite state and a
    positive definite P (Cholesky) with sd below the blow-up limits; NaN sd before aligned,
    inf when not finite."""
    if aligned:
        d = P.diagonal()
        finite = bool(np.isfinite(P).all()) and all(math.isfinite(v) for v in x)
        sd = np.sqrt(np.maximum(d, 0.0)).tolist() if finite else [math.inf] * N
        spd = finite
        if finite:
            try:
                np.linalg.cholesky(0.5 * (P + P.T))
            except np.linalg.LinAlgError:
                spd = False
    else:
        sd = [math.nan] * N
        spd = False
    pos_sd, vel_sd, att_sd = max(sd[0:3]), max(sd[3:6]), max(sd[6:9])
    healthy = (spd and pos_sd < st.healthy_pos_sd_max_m
               and vel_sd < st.healthy_vel_sd_max_m_s and att_sd < st.healthy_att_sd_max_rad)
    converged = (healthy and pos_sd < st.converged_pos_sd_m
                 and vel_sd < st.converged_vel_sd_m_s and att_sd < st.converged_att_sd_rad)
    return sd, converged, healthy
