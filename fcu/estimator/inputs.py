"""What the estimator reads: IMU samples and external poses (world ENU, body FLU, us)."""

from __future__ import annotations

import math
from typing import NamedTuple

from common.quaternion import Quat, Vec3


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

