"""Set-point limits (accelerations, rotation rate) that every actuator can follow; pure numpy.

`manual.fit_envelope` fits POSCTL's, OFFBOARD's and HOLD's limits with `judge`: the nominal
wrench of a reference (fcu.feasibility: f_b = m R^T (a - g_W), tau_b = J omega' + omega x J
omega, Omega = A^+ [f_b; tau_b], tilt alpha_i = atan2(lat_i, ver_i)) is evaluated

* at a fixed set of attitudes (`attitudes`): the entry attitude turned to `YAW_SAMPLES` yaws
  and, for rotations about any axis, `SO3_SAMPLES` attitudes covering SO(3) (a super-Fibonacci
  spiral, deterministic); attitudes where merely hovering exceeds the rotor limit are
  skipped (a pose there is refused elsewhere, or cannot be shaped);
* with every corner of the acceleration limits (8 horizontal directions x up, down, level,
  and rest) and the rotation rate and acceleration of either sign about `ROTATION_AXES` (body
  +-x, +-y, +-z and the 8 diagonals; POSCTL: the world vertical).

Three needs, each against `Envelope`'s limits:

* rotor speed at every corner <= `limit` (85 % of w_max);
* tilt rate of rotating at the rotation rate W: W |d alpha_i / d theta| (the derivative of
  alpha along q exp(theta n), the world acceleration held, in closed form: d/dtheta R^T v =
  (R^T v) x n) <= `tilt_limit`; the rate fits
  in closed form, W = tilt_limit / max |d alpha / d theta| (omega x J omega, a few tenths of
  a newton metre at 90 deg/s, is left out of the derivative);
* tilt step: the shapers change acceleration (and rotation acceleration) step-wise, from rest
  to a corner or, reversing, from the opposite corner, and each step steps the tilts. The
  servo must catch up within TILT_STEP_S (50 ms, half of COM_ACT_RATE_T, after which the
  actuator monitor reports a rate-limited servo): |d alpha_i| w_i' <= tilt_rate_max TILT_STEP_S,
  with w_i' = min(1, |Omega_i| / Omega_hover) the rotor's share of its hover thrust (the lesser
  of before and after): a servo's lag misplaces thrust x angle, so a rotor carrying half its
  hover share may step twice as far.

Near zero thrust a rotor's tilt is undefined (alpha_i flips by pi as Omega_i passes through
zero, at two body directions of gravity per rotor), and no finite rate fits there: rotors below
`THRUST_FLOOR` of their hover share are left out of the tilt-rate need (the step need weighs
them by their thrust already).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from fcu.feasibility import TILT_STEP_S, Envelope

YAW_SAMPLES = 12
SO3_SAMPLES = 64
THRUST_FLOOR = 0.2  # share of a rotor's hover thrust below which its tilt rate is not judged
_PHI, _PSI = math.sqrt(2.0), 1.533751168755204288118041  # super-Fibonacci constants


def _axes() -> np.ndarray:
    ax = [(1.0, 0.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, -1.0, 0.0),
          (0.0, 0.0, 1.0), (0.0, 0.0, -1.0)]
    ax += [(x, y, z) for x in (1.0, -1.0) for y in (1.0, -1.0) for z in (1.0, -1.0)]
    a = np.array(ax)
    return np.asarray(a / np.linalg.norm(a, axis=1, keepdims=True))


ROTATION_AXES = _axes()  # body-frame unit axes (14 x 3)


def so3_sample(n: int = SO3_SAMPLES) -> np.ndarray:
    """n unit quaternions (w, x, y, z) spread over SO(3) (super-Fibonacci spiral)."""
    s = np.arange(n) + 0.5
    r, big_r = np.sqrt(s / n), np.sqrt(1.0 - s / n)
    a, b = 2.0 * np.pi * s / _PHI, 2.0 * np.pi * s / _PSI
    return np.stack([r * np.sin(a), r * np.cos(a), big_r * np.sin(b), big_r * np.cos(b)], 1)


def q_mul_n(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton products of quaternion rows (broadcast, ... x 4)."""
    w1, x1, y1, z1 = np.moveaxis(a, -1, 0)
    w2, x2, y2, z2 = np.moveaxis(b, -1, 0)
    return np.stack([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2],
                    -1)


def q_exp_n(v: np.ndarray) -> np.ndarray:
    """exp of rotation vectors (... x 3) as unit quaternions (... x 4)."""
    th = np.linalg.norm(v, axis=-1, keepdims=True)
    k = np.where(th > 1e-12, np.sin(0.5 * th) / np.maximum(th, 1e-300), 0.5)
    return np.concatenate([np.cos(0.5 * th), v * k], -1)


def rotate_inv_n(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """R(q)^T v (world to body) for rows of q (... x 4) and v (... x 3), broadcast."""
    u = -q[..., 1:]
    w = q[..., :1]
    t = 2.0 * np.cross(u, v)
    return np.asarray(v + w * t + np.cross(u, t))


def attitudes(q0: tuple[float, float, float, float], any_axis: bool) -> np.ndarray:
    """q0 turned about the world vertical to YAW_SAMPLES yaws, and with `any_axis` the
    SO(3) sample too (rows, w x y z)."""
    yaw = np.arange(YAW_SAMPLES) * (2.0 * np.pi / YAW_SAMPLES)
    turns = q_exp_n(np.stack([np.zeros_like(yaw), np.zeros_like(yaw), yaw], 1))
    out = q_mul_n(turns, np.array(q0, dtype=np.float64))
    return np.concatenate([out, so3_sample()]) if any_axis else out


def corners(acc_xy: float, acc_up: float, acc_down: float) -> np.ndarray:
    """World accelerations (ENU): 8 horizontal directions x (up, down, level), and rest."""
    ang = np.arange(8) * (np.pi / 4.0)
    rows = [(acc_xy * math.cos(t), acc_xy * math.sin(t), az) for t in ang
            for az in (acc_up, -acc_down, 0.0)]
    return np.array([*rows, (0.0, 0.0, 0.0)])


class Needs(NamedTuple):
    """The worst of each need over the samples (module docstring), and how many attitudes
    were skipped."""

    rotor_ratio: float  # highest rotor speed / limit
    tilt_per_rad: float  # highest |d alpha / d theta| (rad per rad of rotation)
    step_ratio: float  # highest weighted tilt step / (tilt_rate_max TILT_STEP_S)
    skipped: int


def _omega(env: Envelope, q: np.ndarray, a: np.ndarray, w: np.ndarray,
           wd: np.ndarray) -> np.ndarray:
    """Omega (... x 2n) of the nominal wrench, broadcast over the leading axes; the force's
    and the torque's parts are allocated apart (A^+ is linear) and added."""
    v = env.vehicle
    g = np.array([0.0, 0.0, v.gravity_m_s2])
    force = v.mass_kg * rotate_inv_n(q, a + g)
    jd = np.array(v.inertia_diag_kg_m2)
    torque = jd * wd + np.cross(w, jd * w)
    return np.asarray(force @ env.pinv_t[:3] + torque @ env.pinv_t[3:])


def _mag_alpha(om: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    lat, ver = om[..., 0::2], om[..., 1::2]
    return np.hypot(lat, ver), np.arctan2(lat, ver)


def _wrap(x: np.ndarray) -> np.ndarray:
    return np.asarray(np.abs(np.remainder(x + np.pi, 2.0 * np.pi) - np.pi))


def judge(env: Envelope, q0: tuple[float, float, float, float], acc_xy: float, acc_up: float,
          acc_down: float, rate_rad_s: float, rate_acc_rad_s2: float, any_axis: bool) -> Needs:
    """The needs of the module docstring for these limits at q0's attitude set."""
    v = env.vehicle
    share = v.mass_kg * v.gravity_m_s2 / v.n_rotors / v.thrust_coeff  # Omega of a hover share
    q = attitudes(q0, any_axis)
    zero = np.zeros(3)
    hover_mag, _ = _mag_alpha(_omega(env, q, zero, zero, zero))
    keep = np.sqrt(hover_mag.max(axis=1)) <= env.limit
    q = q[keep]
    skipped = int(np.count_nonzero(~keep))
    if len(q) == 0:
        return Needs(math.inf, math.inf, math.inf, skipped)
    if any_axis:
        axes = np.broadcast_to(ROTATION_AXES, (len(q), *ROTATION_AXES.shape))  # N x M x 3
    else:
        axes = rotate_inv_n(q, np.array([0.0, 0.0, 1.0]))[:, None, :]  # world vertical
    acc = corners(acc_xy, acc_up, acc_down)  # K x 3
    qn = q[:, None, None, :]  # N x 1 x 1 x 4
    an = acc[None, :, None, :]  # 1 x K x 1 x 3
    ax = axes[:, None, :, :]  # N x 1 x M x 3
    # rotor speed: every corner with the rotation rate and acceleration of either sign
    rotor = 0.0
    for sign in (1.0, -1.0):
        om = _omega(env, qn, an, sign * rate_rad_s * ax, sign * rate_acc_rad_s2 * ax)
        sq = om[..., 0::2] ** 2 + om[..., 1::2] ** 2
        rotor = max(rotor, float(np.sqrt(np.sqrt(sq.max()))) / env.limit)
    # tilt rate per radian of rotation about each axis, the world acceleration held:
    # d/dtheta R(q exp(theta n))^T v = (R^T v) x n, so d Omega = [m (R^T (a - g_W)) x n; 0] A^+T
    f_b = v.mass_kg * rotate_inv_n(qn, an + np.array([0.0, 0.0, v.gravity_m_s2]))
    om = np.asarray(np.concatenate([f_b, np.zeros_like(f_b)], -1) @ env.pinv_t)  # N x K x 1
    d_om = np.asarray(np.concatenate([np.cross(f_b, ax), np.zeros((*np.broadcast_shapes(
        f_b.shape, ax.shape)[:-1], 3))], -1) @ env.pinv_t)  # N x K x M
    lat, ver, dlat, dver = om[..., 0::2], om[..., 1::2], d_om[..., 0::2], d_om[..., 1::2]
    sq = lat * lat + ver * ver
    per_rad = np.where(np.sqrt(sq) >= THRUST_FLOOR * share,
                       np.abs(ver * dlat - lat * dver) / np.maximum(sq, 1e-300), 0.0)
    # tilt steps: rest -> corner and opposite corner -> corner; and a rotation acceleration
    # step about each axis from rest (its torque is small: judged apart)
    step = 0.0
    to_mag, to_alpha = _mag_alpha(_omega(env, qn[:, :, 0], an[:, :, 0], zero, zero))
    wd = rate_acc_rad_s2 * ax[:, 0]
    for fr in (_omega(env, qn[:, :, 0], zero, zero, zero),
               _omega(env, qn[:, :, 0], -an[:, :, 0], zero, zero)):
        fr_mag, fr_alpha = _mag_alpha(fr)
        weight = np.minimum(1.0, np.minimum(to_mag, fr_mag) / share)
        step = max(step, float((_wrap(to_alpha - fr_alpha) * weight).max()))
    rest_mag, rest_alpha = _mag_alpha(_omega(env, qn[:, 0], zero, zero, zero))
    for sign in (1.0, -1.0):
        w_mag, w_alpha = _mag_alpha(_omega(env, qn[:, 0], zero, zero, sign * wd))
        weight = np.minimum(1.0, np.minimum(w_mag, rest_mag) / share)
        step = max(step, float((_wrap(w_alpha - rest_alpha) * weight).max()))
    return Needs(rotor, float(per_rad.max()), step / (env.tilt_rate_max * TILT_STEP_S),
                 skipped)


def fitted_rate(needs: Needs, env: Envelope, rate_rad_s: float) -> float:
    """The rotation rate, lowered to what the tilt servos follow (module docstring)."""
    if needs.tilt_per_rad * rate_rad_s <= env.tilt_limit:
        return rate_rad_s
    return env.tilt_limit / needs.tilt_per_rad
