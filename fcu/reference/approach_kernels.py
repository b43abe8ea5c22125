"""The compiled kernels of an approach (`fcu.reference.approach`): the offset of each of its
six components at a time (x0 (1 - B(t / D)) plus its starting rates' quintic to rest), the
reference they give with the set-point, its rows for the envelope's check, and the share of
the approach limits used; pure."""

from __future__ import annotations

import math

import numpy as np

from common.jit import njit
from fcu.control.dualquat import Quat, Vec3, cross, q_exp, q_mul, q_rotate_inv, right_jacobian_inv
from fcu.reference.trajectory import quintic_poly


@njit
def _right_jacobians(phi: Vec3, x: Vec3, y: Vec3) -> tuple[Vec3, Vec3]:
    """J_r(phi) x and J_r(phi) y (`right_jacobian`), the coefficients taken once."""
    th2 = phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2]
    if th2 < 1e-12:
        a, b = 0.5, 1.0 / 6.0
    else:
        th = math.sqrt(th2)
        a, b = (1.0 - math.cos(th)) / th2, (th - math.sin(th)) / (th2 * th)
    px, py = cross(phi, x), cross(phi, y)
    ppx, ppy = cross(phi, px), cross(phi, py)
    return ((x[0] - a * px[0] + b * ppx[0], x[1] - a * px[1] + b * ppx[1],
             x[2] - a * px[2] + b * ppx[2]),
            (y[0] - a * py[0] + b * ppy[0], y[1] - a * py[1] + b * ppy[1],
             y[2] - a * py[2] + b * ppy[2]))


@njit
def right_jacobian(phi: Vec3, x: Vec3) -> Vec3:
    """J_r(phi) x: the body rate of exp(phi) when phi changes at x."""
    return _right_jacobians(phi, x, x)[0]


@njit
def offset_rate(phi: Vec3, w: Vec3) -> Vec3:
    """How the attitude offset phi changes for a body rate w of exp(phi)
    (`fcu.control.dualquat.right_jacobian_inv`); beyond 3 rad, where the inverse grows without bound
    towards 2 pi, w itself."""
    if math.sqrt(phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2]) > 3.0:
        return w
    return right_jacobian_inv(phi, w)


def quintic_to_rest(x0: float, v0: float, a0: float, d: float) -> tuple[float, ...]:
    """Coefficients k0..k5 of x(s) = sum k_j s^j, s = tau / d in [0, 1], with x, dx/dtau,
    d^2x/dtau^2 = (x0, v0, a0) at s = 0 and (0, 0, 0) at s = 1."""
    v, a = v0 * d, a0 * d * d
    return (x0, v, 0.5 * a, -(20.0 * x0 + 12.0 * v + 3.0 * a) / 2.0,
            (30.0 * x0 + 16.0 * v + 3.0 * a) / 2.0, -(12.0 * x0 + 6.0 * v + a) / 2.0)


_quintic = njit(quintic_poly)  # the one minimum-jerk polynomial, compiled for `blend`


@njit
def blend(s: float, r: float) -> tuple[float, float, float]:
    """B(s) from 0 to 1 on [0, 1] and its first two s-derivatives, zero at both ends: the
    minimum-jerk 10 s^3 - 15 s^4 + 6 s^5 for r = 0; for 0 < r <= 1/2 a cruise at
    1 / (1 - r) between ramps of share r whose rate is the minimum-jerk blend of the ramp
    (so B'' is continuous: no step in an acceleration)."""
    if s <= 0.0:
        return 0.0, 0.0, 0.0
    if s >= 1.0:
        return 1.0, 0.0, 0.0
    if r <= 0.0:
        return _quintic(s)
    k = 1.0 / (1.0 - r)
    if r < s < 1.0 - r:
        return k * (s - 0.5 * r), k, 0.0
    u = s / r if s <= r else (1.0 - s) / r
    u2 = u * u
    big_q = u2 * u2 * (2.5 - 3.0 * u + u2)  # the integral of the ramp's rate
    q = _quintic(u)[0]
    dq = 30.0 * u2 * (1.0 - u) * (1.0 - u)  # q's rate, factored as the pinned figures have it
    if s <= r:
        return k * r * big_q, k * q, k * dq / r
    return 1.0 - k * r * big_q, k * q, -k * dq / r


@njit
def _component(k: np.ndarray, j: int, d: float, tau: float) -> tuple[float, float, float]:
    """Component j's value, rate and acceleration at tau (zero from tau >= d on): its
    start k[j, 0] times 1 - B(s) (`blend`, cruise share k[j, 6]) plus the quintic of its
    start's rates, k[j, 1..5], over the share k[j, 7] of d. With a share below 1 the rates
    are braked over it with a free end (from k[j, 8], where that brake starts, to rest at
    0: `fcu.reference.approach.free_end`) and the blend takes the start less k[j, 8]."""
    if tau >= d:
        return 0.0, 0.0, 0.0
    s = max(tau, 0.0) / d
    x0, c1, c2, c3, c4, c5 = k[j, 0], k[j, 1], k[j, 2], k[j, 3], k[j, 4], k[j, 5]
    b, db, ddb = blend(s, k[j, 6])
    rho = k[j, 7]
    if rho == 1.0:
        x = x0 * (1.0 - b) + s * (c1 + s * (c2 + s * (c3 + s * (c4 + s * c5))))
        dx = (-x0 * db + c1 + s * (2.0 * c2 + s * (3.0 * c3 + s * (4.0 * c4 + s * 5.0 * c5)))
              ) / d
        ddx = (-x0 * ddb + 2.0 * c2 + s * (6.0 * c3 + s * (12.0 * c4 + s * 20.0 * c5))) / \
            (d * d)
        return x, dx, ddx
    stop = k[j, 8]  # where the rates' brake starts (its end free), from its rest
    x0 -= stop
    x, dx, ddx = x0 * (1.0 - b), -x0 * db / d, -x0 * ddb / (d * d)
    dr = rho * d
    if tau < dr:
        u = max(tau, 0.0) / dr
        b0, db0, ddb0 = blend(u, 0.0)
        x += stop * (1.0 - b0) + u * (c1 + u * (c2 + u * (c3 + u * (c4 + u * c5))))
        dx += (-stop * db0 + c1 + u * (2.0 * c2 + u * (3.0 * c3 + u * (4.0 * c4 +
                                                                     u * 5.0 * c5)))) / dr
        ddx += (-stop * ddb0 + 2.0 * c2 + u * (6.0 * c3 + u * (12.0 * c4 + u * 20.0 * c5))
                ) / (dr * dr)
    return x, dx, ddx


@njit
def offset_kernel(k: np.ndarray, d: float, tau: float) -> tuple[Vec3, Vec3, Vec3, Vec3, Vec3,
                                                                 Vec3]:
    """(e, de, dde, eps, deps, ddeps) at tau seconds into the approach."""
    e0, de0, dde0 = _component(k, 0, d, tau)
    e1, de1, dde1 = _component(k, 1, d, tau)
    e2, de2, dde2 = _component(k, 2, d, tau)
    r0, dr0, ddr0 = _component(k, 3, d, tau)
    r1, dr1, ddr1 = _component(k, 4, d, tau)
    r2, dr2, ddr2 = _component(k, 5, d, tau)
    return ((e0, e1, e2), (de0, de1, de2), (dde0, dde1, dde2), (r0, r1, r2), (dr0, dr1, dr2),
            (ddr0, ddr1, ddr2))


@njit
def reference_kernel(p: Vec3, v: Vec3, a: Vec3, q: Quat, w: Vec3, k: np.ndarray, d: float,
                     tau_sp: float, tau: float) -> tuple[Vec3, Quat, Vec3, Vec3, Vec3, Vec3]:
    """The reference (p, q, v, a, omega, omega_dot) of the set-point extrapolated tau_sp
    seconds from its anchor plus the offset tau seconds into the approach."""
    e, de, dde, eps, deps, ddeps = offset_kernel(k, d, tau)
    h = 0.5 * tau_sp * tau_sp
    q_sp = q_mul(q, q_exp((w[0] * tau_sp, w[1] * tau_sp, w[2] * tau_sp)))
    q_e = q_exp(eps)
    w_seen = q_rotate_inv(q_e, w)
    w_e = right_jacobian(eps, deps)
    return ((p[0] + v[0] * tau_sp + a[0] * h + e[0], p[1] + v[1] * tau_sp + a[1] * h + e[1],
             p[2] + v[2] * tau_sp + a[2] * h + e[2]),
            q_mul(q_sp, q_e),
            (v[0] + a[0] * tau_sp + de[0], v[1] + a[1] * tau_sp + de[1],
             v[2] + a[2] * tau_sp + de[2]),
            (a[0] + dde[0], a[1] + dde[1], a[2] + dde[2]),
            (w_seen[0] + w_e[0], w_seen[1] + w_e[1], w_seen[2] + w_e[2]),
            right_jacobian(eps, ddeps))


@njit
def reference_rows(p: Vec3, v: Vec3, a: Vec3, q: Quat, w: Vec3, k: np.ndarray, d: float,
          taus: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """`reference_kernel`'s q (4 x n), a, omega, omega_dot (3 x n) at each tau (set-point
    and approach start together); where w = 0, exp(w tau) is taken once per sign of tau."""
    n = taus.shape[0]
    qs, acc, rate, rate_dot = np.empty((4, n)), np.empty((3, n)), np.empty((3, n)), \
        np.empty((3, n))
    still = w[0] == 0.0 and w[1] == 0.0 and w[2] == 0.0
    q_signs = (q_mul(q, q_exp((w[0] * 1.0, w[1] * 1.0, w[2] * 1.0))),
               q_mul(q, q_exp((w[0] * -1.0, w[1] * -1.0, w[2] * -1.0))))
    for i in range(n):
        tau = taus[i]
        _, _, dde, eps, deps, ddeps = offset_kernel(k, d, tau)
        q_sp = q_signs[int(math.copysign(1.0, tau) < 0.0)] if still else \
            q_mul(q, q_exp((w[0] * tau, w[1] * tau, w[2] * tau)))
        q_e = q_exp(eps)
        w_seen = q_rotate_inv(q_e, w)
        w_e, wd = _right_jacobians(eps, deps, ddeps)
        qs[0, i], qs[1, i], qs[2, i], qs[3, i] = q_mul(q_sp, q_e)
        acc[0, i], acc[1, i], acc[2, i] = a[0] + dde[0], a[1] + dde[1], a[2] + dde[2]
        for j in range(3):
            rate[j, i], rate_dot[j, i] = w_seen[j] + w_e[j], wd[j]
    return qs, acc, rate, rate_dot


@njit
def kinematic_ratios(k: np.ndarray, d: float, taus: np.ndarray, lim: np.ndarray
                     ) -> np.ndarray:
    """The largest share of each approach limit the offset uses: lim = (speed_xy, speed_up,
    speed_down, acc_xy, acc_up, acc_down, rotation rate, rotation acceleration)."""
    worst = np.zeros(8)
    for i in range(taus.shape[0]):
        _, de, dde, _, deps, ddeps = offset_kernel(k, d, taus[i])
        worst[0] = max(worst[0], math.hypot(de[0], de[1]) / lim[0])
        if de[2] > 0.0:
            worst[1] = max(worst[1], de[2] / lim[1])
        else:
            worst[2] = max(worst[2], -de[2] / lim[2])
        worst[3] = max(worst[3], math.hypot(dde[0], dde[1]) / lim[3])
        if dde[2] > 0.0:
            worst[4] = max(worst[4], dde[2] / lim[4])
        else:
            worst[5] = max(worst[5], -dde[2] / lim[5])
        worst[6] = max(worst[6], math.sqrt(deps[0] ** 2 + deps[1] ** 2 + deps[2] ** 2) / lim[6])
        worst[7] = max(worst[7], math.sqrt(ddeps[0] ** 2 + ddeps[1] ** 2 + ddeps[2] ** 2) /
                       lim[7])
    return worst
