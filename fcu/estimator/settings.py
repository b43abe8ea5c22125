"""The estimator's settings (EKF2's parameter names where EKF2 has the figure).

Noises are per-sample sigmas for the IMU (Sola eq. 271-272, EKF2's daxVar/dvxVar) and
densities for the bias random walks (Sola eq. 273-274); times in seconds. The parameter
table (`fcu.params`) maps its EKF_* entries onto these fields.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class EstimatorSettings:
    """The filter's noises, gates, alignment and health thresholds (checked on creation)."""

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
