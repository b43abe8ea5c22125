"""Desired trajectories with analytic derivatives (paper eqs. 31-32, MODEL.md section 5).

Each trajectory maps time in seconds to a `Reference`: pose, world velocity and acceleration,
body rate and its derivative. Nothing here differentiates numerically.
"""

from __future__ import annotations

import math
from typing import Protocol

from common.config import TrajectoryConfig
from fcu.dualquat import Q_IDENTITY, Quat, Vec3, q_exp
from fcu.tracker import Reference

_ZERO: Vec3 = (0.0, 0.0, 0.0)


class Trajectory(Protocol):
    def sample(self, t_s: float) -> Reference: ...


class Hover:
    """Hold a fixed pose (Case II)."""

    def __init__(self, p_enu_m: Vec3, q_enu_flu: Quat = Q_IDENTITY) -> None:
        self.ref = Reference(p_enu_m, q_enu_flu, _ZERO, _ZERO, _ZERO, _ZERO)

    def sample(self, t_s: float) -> Reference:
        return self.ref


def quintic(s: float) -> tuple[float, float, float]:
    """Minimum-jerk blend 10 s^3 - 15 s^4 + 6 s^5 on [0, 1] and its first two derivatives."""
    if s <= 0.0:
        return 0.0, 0.0, 0.0
    if s >= 1.0:
        return 1.0, 0.0, 0.0
    s2 = s * s
    return (s2 * s * (10.0 - 15.0 * s + 6.0 * s2),
            30.0 * s2 * (1.0 - 2.0 * s + s2),
            60.0 * s * (1.0 - 3.0 * s + 2.0 * s2))


class FigureEight:
    """Case I: quintic rise, hover, the figure-infinity of eq. (31), hover.

    p_d = p0 + [0, 0, h] + A [sin 2T, sin T, 1 - cos 2T], theta_d = T n with
    T = pi (1 - cos(pi (t - t1) / (t2 - t1))) on [t1, t2] and T = 2 pi after t2 (the paper's
    T = 0 would make the attitude jump; MODEL.md section 5).
    """

    def __init__(self, cfg: TrajectoryConfig) -> None:
        self.p0 = cfg.position_enu_m
        self.height = cfg.rise_height_m
        self.t_rise = cfg.rise_end_s
        self.t1 = cfg.figure_start_s
        self.t2 = cfg.figure_end_s
        self.amp = cfg.amplitude_m
        self.axis = cfg.axis_enu

    def phase(self, t_s: float) -> tuple[float, float, float]:
        """T(t), T'(t), T''(t) of eq. (32), held at 2 pi after the figure."""
        if t_s <= self.t1:
            return 0.0, 0.0, 0.0
        if t_s >= self.t2:
            return 2.0 * math.pi, 0.0, 0.0
        k = math.pi / (self.t2 - self.t1)
        x = k * (t_s - self.t1)
        return (math.pi * (1.0 - math.cos(x)), math.pi * k * math.sin(x),
                math.pi * k * k * math.cos(x))

    def sample(self, t_s: float) -> Reference:
        x0, y0, z0 = self.p0
        s, ds, dds = quintic(t_s / self.t_rise)
        h = self.height
        z, vz, az = z0 + h * s, h * ds / self.t_rise, h * dds / (self.t_rise * self.t_rise)
        T, dT, ddT = self.phase(t_s)
        a = self.amp
        s1, c1, s2, c2 = math.sin(T), math.cos(T), math.sin(2.0 * T), math.cos(2.0 * T)
        # p = A [sin 2T, sin T, 1 - cos 2T]; chain rule with T', T''.
        p = (x0 + a * s2, y0 + a * s1, z + a * (1.0 - c2))
        dp_dT = (2.0 * a * c2, a * c1, 2.0 * a * s2)
        d2p_dT2 = (-4.0 * a * s2, -a * s1, 4.0 * a * c2)
        v = (dp_dT[0] * dT, dp_dT[1] * dT, vz + dp_dT[2] * dT)
        acc = (d2p_dT2[0] * dT * dT + dp_dT[0] * ddT,
               d2p_dT2[1] * dT * dT + dp_dT[1] * ddT,
               az + d2p_dT2[2] * dT * dT + dp_dT[2] * ddT)
        n = self.axis
        q = q_exp((T * n[0], T * n[1], T * n[2]))
        # Rotation about a fixed axis: the body rate equals the world rate, T' n.
        w = (dT * n[0], dT * n[1], dT * n[2])
        wd = (ddT * n[0], ddT * n[1], ddT * n[2])
        return Reference(p, q, v, acc, w, wd)


def make_trajectory(cfg: TrajectoryConfig) -> Trajectory:
    if cfg.kind == "hover":
        return Hover(cfg.position_enu_m)
    return FigureEight(cfg)
