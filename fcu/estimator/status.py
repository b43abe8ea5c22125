"""What the estimator reports: the flight checks' health and the full status."""

from __future__ import annotations

from typing import NamedTuple

from common.quaternion import Vec3
from fcu.estimator.settings import EstimatorSettings


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



def sd_verdict(st: EstimatorSettings, sd: list[float], spd: bool) -> tuple[bool, bool]:
    """(converged, healthy) from the 15 standard deviations (NaN before aligned, inf when
    not finite) and whether P is positive definite: healthy needs spd and the sd below the
    blow-up limits (health's cheap variant: `fcu.estimator.readout.variance_code`)."""
    pos_sd, vel_sd, att_sd = max(sd[0:3]), max(sd[3:6]), max(sd[6:9])
    healthy = (spd and pos_sd < st.healthy_pos_sd_max_m
               and vel_sd < st.healthy_vel_sd_max_m_s and att_sd < st.healthy_att_sd_max_rad)
    converged = (healthy and pos_sd < st.converged_pos_sd_m
                 and vel_sd < st.converged_vel_sd_m_s and att_sd < st.converged_att_sd_rad)
    return converged, healthy
