"""Desired trajectories with analytic derivatives (paper eqs. 31-32, docs/model.md#scenarios).

Each trajectory maps time in seconds to a `Reference`: pose, world velocity and acceleration,
body rate and its derivative. Nothing here differentiates numerically.

The two profiles, the minimum-jerk quintic and the figure-infinity of eqs. (31)-(32), live here
once; `fcu.mission` flies the same functions (mission items 22, 16, 19, 21, 31000 and 31001).

Breakpoints: a sample at exactly a profile's start or end is its right-hand limit, the value
that holds over the control period that begins there. At the figure's start T'' jumps from 0
to pi k^2 (docs/model.md#scenarios), so the sample at that instant already carries the figure's
feed-forward; at its end it is the hold.

The formulas of the profiles (`quintic_poly`, `figure_phase_inside`, `figure_path`) take
floats or numpy arrays alike (`xp` = math or numpy), so the envelope check of
`fcu.envelope.feasibility` samples a whole segment at once with the very expressions that fly.
"""

from __future__ import annotations

import math
import struct
from functools import cached_property
from typing import Any, NamedTuple, Protocol

import numpy as np

from common.config.scenario import TrajectoryConfig
from common.quaternion import q_exp_many
from fcu.control.dualquat import Q_IDENTITY, Quat, Vec3, q_exp, q_mul, q_rotate_inv
from fcu.stages import Reference

_ZERO: Vec3 = (0.0, 0.0, 0.0)
TWO_PI = 2.0 * math.pi


class Trajectory(Protocol):
    def sample(self, t_s: float) -> Reference: ...


class Hover:
    """Hold a fixed pose (Case II)."""

    def __init__(self, p_enu_m: Vec3, q_enu_flu: Quat = Q_IDENTITY) -> None:
        self.ref = Reference(p_enu_m, q_enu_flu, _ZERO, _ZERO, _ZERO, _ZERO)

    def sample(self, t_s: float) -> Reference:
        return self.ref


# ----------------------------------------------------------------------------------------
# Minimum-jerk quintic
# ----------------------------------------------------------------------------------------


QUINTIC_PEAK_RATE = 1.875  # the quintic's top rate over its mean, 30 s^2 (1 - s)^2 at s = 1/2


def quintic_poly(s: Any) -> tuple[Any, Any, Any]:
    """10 s^3 - 15 s^4 + 6 s^5 and its first two derivatives, unclamped (floats or arrays)."""
    s2 = s * s
    return (s2 * s * (10.0 - 15.0 * s + 6.0 * s2),
            30.0 * s2 * (1.0 - 2.0 * s + s2),
            60.0 * s * (1.0 - 3.0 * s + 2.0 * s2))


def quintic(s: float) -> tuple[float, float, float]:
    """The minimum-jerk blend on [0, 1], held at 0 before and at 1 from s = 1 on.

    Position, velocity and acceleration are continuous at both ends (only the jerk jumps),
    so the value at s = 0 and s = 1 is both one-sided limit."""
    if s < 0.0:
        return 0.0, 0.0, 0.0
    if s >= 1.0:
        return 1.0, 0.0, 0.0
    return quintic_poly(s)


# ----------------------------------------------------------------------------------------
# Figure-infinity (eqs. 31-32)
# ----------------------------------------------------------------------------------------


def figure_phase_inside(tau: Any, duration: float, xp: Any = math) -> tuple[Any, Any, Any]:
    """T = pi (1 - cos(pi tau / D)) of eq. (32), T' and T'' (floats or arrays).

    The expressions of the open interval (0, D); evaluated at tau = 0 or D they give the
    one-sided limits from inside the figure."""
    k = math.pi / duration
    x = k * tau
    return (math.pi * (1.0 - xp.cos(x)), math.pi * k * xp.sin(x),
            math.pi * k * k * xp.cos(x))


def figure_phase(tau: float, duration: float) -> tuple[float, float, float]:
    """T, T', T'' at tau = t - t_start: 0 before the figure, eq. (32) on [0, D), held at 2 pi
    from D on (the paper's T = 0 would make the attitude jump; docs/model.md#scenarios).

    Right-hand limits at both breakpoints: at tau = 0, T'' = pi k^2 (k = pi / D), not 0."""
    if tau < 0.0:
        return 0.0, 0.0, 0.0
    if tau >= duration:
        return TWO_PI, 0.0, 0.0
    return figure_phase_inside(tau, duration)


def figure_path(amp: float, T: Any, dT: Any, ddT: Any,
                xp: Any = math) -> tuple[tuple[Any, Any, Any], ...]:
    """Offset A [sin 2T, sin T, 1 - cos 2T] of eq. (31) from the figure's start (ENU), its
    velocity and acceleration by the chain rule with T', T'' (floats or arrays)."""
    s1, c1, s2, c2 = xp.sin(T), xp.cos(T), xp.sin(2.0 * T), xp.cos(2.0 * T)
    off = (amp * s2, amp * s1, amp * (1.0 - c2))
    dp_dT = (2.0 * amp * c2, amp * c1, 2.0 * amp * s2)
    d2p_dT2 = (-4.0 * amp * s2, -amp * s1, 4.0 * amp * c2)
    v = (dp_dT[0] * dT, dp_dT[1] * dT, dp_dT[2] * dT)
    acc = (d2p_dT2[0] * dT * dT + dp_dT[0] * ddT,
           d2p_dT2[1] * dT * dT + dp_dT[1] * ddT,
           d2p_dT2[2] * dT * dT + dp_dT[2] * ddT)
    return off, v, acc


class FigureShape(NamedTuple):
    """What a figure's path flown in 1 s is at normalised times sigma before its start pose
    places it (`FigureInfinity.path`): T, T', T'' (`figure_phase_inside`), the offset, its
    velocity and acceleration (`figure_path`) and exp(T n) (`q_exp_many`), all arrays."""

    T: Any
    dT: Any
    ddT: Any
    offset: tuple[Any, Any, Any]
    velocity: tuple[Any, Any, Any]
    acceleration: tuple[Any, Any, Any]
    turn: tuple[Any, Any, Any, Any]


def figure_shape(amp: float, axis_enu: Vec3, sigma: np.ndarray) -> FigureShape:
    """The `FigureShape` of a figure of amplitude `amp` about `axis_enu` at sigma."""
    T, dT, ddT = figure_phase_inside(sigma, 1.0, np)
    off, v, acc = figure_path(amp, T, dT, ddT, np)
    n = axis_enu
    return FigureShape(T, dT, ddT, off, v, acc, q_exp_many(T * n[0], T * n[1], T * n[2]))


class FigureInfinity:
    """The figure-infinity of eqs. (31)-(32) from a start pose (p0, q0), tau = t - t_start:

    p = p0 + A [sin 2T, sin T, 1 - cos 2T] (ENU), q = exp(T n) q0 (a rotation about the fixed
    world axis n, not normalised), T = pi (1 - cos(pi tau / D)) on [0, D], held at 2 pi after.
    The body rate is R(q)^T T' n = R(q0)^T T' n (exp(T n) leaves n fixed). q0 = None is the
    identity (the paper's Case I), which skips the product with q0.
    """

    def __init__(self, amp: float, duration: float, axis_enu: Vec3, p0: Vec3 = _ZERO,
                 q0: Quat | None = None) -> None:
        self.amp, self.duration, self.n, self.p0, self.q0 = amp, duration, axis_enu, p0, q0
        self.n_body = axis_enu if q0 is None else q_rotate_inv(q0, axis_enu)
        self.end = self._end()

    @cached_property
    def start(self) -> Reference:
        """The reference before the figure (made when first asked)."""
        return self.at(0.0, 0.0, 0.0)

    def phase(self, tau: float) -> tuple[float, float, float]:
        return figure_phase(tau, self.duration)

    def attitude(self, T: Any, dT: Any, ddT: Any, exp: Any = q_exp) -> tuple[Any, Any, Any]:
        """q = exp(T n) q0, body rate and its derivative (`exp`: q_exp, or q_exp_many)."""
        n = self.n
        if exp is q_exp:
            turn = q_exp((T * n[0], T * n[1], T * n[2]))
        else:
            turn = exp(T * n[0], T * n[1], T * n[2])
        return self._turned(turn, dT, ddT)

    def _turned(self, turn: Any, dT: Any, ddT: Any) -> tuple[Any, Any, Any]:
        """`attitude` from turn = exp(T n)."""
        nb = self.n_body
        q = turn if self.q0 is None else q_mul(turn, self.q0)
        return q, (dT * nb[0], dT * nb[1], dT * nb[2]), (ddT * nb[0], ddT * nb[1], ddT * nb[2])

    def _end(self) -> Reference:
        """`at(TWO_PI, 0.0, 0.0)`, the same values: what depends on the amplitude and the
        axis alone is kept by their bits (`_END_SHAPES`: a mission repeats its figures)."""
        key = struct.pack("<4d", self.amp, *self.n)
        shape = _END_SHAPES.get(key)
        if shape is None:
            n = self.n
            shape = (figure_path(self.amp, TWO_PI, 0.0, 0.0),
                     q_exp((TWO_PI * n[0], TWO_PI * n[1], TWO_PI * n[2])))
            if len(_END_SHAPES) >= 64:
                _END_SHAPES.clear()
            _END_SHAPES[key] = shape
        (off, v, acc), turn = shape
        q, w, wd = self._turned(turn, 0.0, 0.0)
        x0, y0, z0 = self.p0
        return Reference((x0 + off[0], y0 + off[1], z0 + off[2]), q, v, acc, w, wd)

    def at(self, T: float, dT: float, ddT: float) -> Reference:
        """The reference at phase T with derivatives T', T''."""
        x0, y0, z0 = self.p0
        off, v, acc = figure_path(self.amp, T, dT, ddT)
        q, w, wd = self.attitude(T, dT, ddT)
        return Reference((x0 + off[0], y0 + off[1], z0 + off[2]), q, v, acc, w, wd)

    def sample(self, tau: float) -> Reference:
        if tau < 0.0:
            return self.start
        if tau >= self.duration:
            return self.end
        return self.at(*figure_phase_inside(tau, self.duration))

    def path(self, sigma: np.ndarray, shape: FigureShape | None = None) -> Reference:
        """The same figure flown in 1 s, at normalised times sigma in [0, 1] (arrays in every
        field); sigma = 0 and 1 give the one-sided limits inside the figure. `shape`: its
        `figure_shape` at sigma, if already made."""
        if shape is None:
            shape = figure_shape(self.amp, self.n, sigma)
        off = shape.offset
        q, w, wd = self._turned(shape.turn, shape.dT, shape.ddT)
        x0, y0, z0 = self.p0
        return Reference((x0 + off[0], y0 + off[1], z0 + off[2]), q, shape.velocity,
                         shape.acceleration, w, wd)

    def phase_instants(self, T: np.ndarray) -> np.ndarray:
        """Normalised times sigma = tau / D at which the phase takes the values T in [0, 2 pi]."""
        return np.arccos(np.clip(1.0 - T / math.pi, -1.0, 1.0)) / math.pi


_END_SHAPES: dict[bytes, tuple[tuple[tuple[float, float, float], ...], Quat]] = {}


# ----------------------------------------------------------------------------------------
# Case I
# ----------------------------------------------------------------------------------------


class FigureEight:
    """Case I: quintic rise, hover, the figure-infinity of eq. (31), hover.

    p_d = p0 + [0, 0, h s(t / t_rise)] + A [sin 2T, sin T, 1 - cos 2T], theta_d = T n with
    T = pi (1 - cos(pi (t - t1) / (t2 - t1))) on [t1, t2] and T = 2 pi after t2 (the paper's
    T = 0 would make the attitude jump; docs/model.md#scenarios).
    """

    def __init__(self, cfg: TrajectoryConfig) -> None:
        self.p0 = cfg.position_enu_m
        self.height = cfg.rise_height_m
        self.t_rise = cfg.rise_end_s
        self.t1 = cfg.figure_start_s
        self.t2 = cfg.figure_end_s
        self.amp = cfg.amplitude_m
        self.axis = cfg.axis_enu
        self.figure = FigureInfinity(cfg.amplitude_m, self.t2 - self.t1, cfg.axis_enu)

    def phase(self, t_s: float) -> tuple[float, float, float]:
        """T(t), T'(t), T''(t) of eq. (32) (right-hand limits at t1 and t2)."""
        return self.figure.phase(t_s - self.t1)

    def sample(self, t_s: float) -> Reference:
        x0, y0, z0 = self.p0
        s, ds, dds = quintic(t_s / self.t_rise)
        h = self.height
        z, vz, az = z0 + h * s, h * ds / self.t_rise, h * dds / (self.t_rise * self.t_rise)
        T, dT, ddT = self.phase(t_s)
        off, v, acc = figure_path(self.amp, T, dT, ddT)
        q, w, wd = self.figure.attitude(T, dT, ddT)
        # The rise and the figure never overlap (rise_end_s <= figure_start_s): one of the two
        # terms of each sum is zero.
        return Reference((x0 + off[0], y0 + off[1], z + off[2]), q,
                         (v[0], v[1], vz + v[2]), (acc[0], acc[1], az + acc[2]), w, wd)


def make_trajectory(cfg: TrajectoryConfig) -> Trajectory:
    if cfg.kind == "hover":
        return Hover(cfg.position_enu_m)
    return FigureEight(cfg)
