"""The one conversion between the code's frames (ENU world, FLU body) and the wire's
(MAVLink local NED, body FRD). Quaternions are (w, x, y, z) everywhere.

x_ned = y_enu, y_ned = x_enu, z_ned = -z_enu; FLU -> FRD flips y and z. The identity
attitude in ENU/FLU (body x east) is yaw = +90 deg in NED.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # common.quaternion compiles with numba: a ground station needs neither
    from common.quaternion import Quat, Vec3

_H = math.sqrt(0.5)


def enu_to_ned(v: Vec3) -> Vec3:
    """A world vector (position, velocity, acceleration, force) from ENU to NED."""
    return (v[1], v[0], -v[2])


ned_to_enu = enu_to_ned  # the map is its own inverse


def flu_to_frd(v: Vec3) -> Vec3:
    """A body vector (velocity, rate, force, torque) from FLU to FRD."""
    return (v[0], -v[1], -v[2])


frd_to_flu = flu_to_frd


_Q_NED_ENU: Quat = (0.0, _H, _H, 0.0)  # pi about (x + y)/sqrt 2: ENU coordinates -> NED
_Q_FLU_FRD: Quat = (0.0, 1.0, 0.0, 0.0)  # pi about x


def q_enu_flu_to_ned_frd(q: Quat) -> Quat:
    """q_ned_frd = q_ned_enu q_enu_flu q_flu_frd, sign chosen with w >= 0: `q_mul` twice
    with the fixed rotations' components written in (the same operations in the same
    order, so the same bits, without two compiled calls' overhead from Python); a
    component not finite takes the compiled calls (whose NaN signs may differ).

    With q_ned_enu = (0, h, h, 0) and q_flu_frd = (0, 1, 0, 0) the product is
    (-ax, aw, az, -ay) of a = q_ned_enu q. The terms the fixed rotations' zeros and ones
    contribute are signed zeros and exact products, which change no sum that is not zero:
    when every component of `a` is non-zero and finite the short form below gives the full
    form's bits; otherwise the full form decides the signs of the zeros (and gives NaN
    where a product overflowed, as the compiled products do)."""
    h = _H
    w, x, y, z = q[0], q[1], q[2], q[3]
    if not math.isfinite(w + x + y + z):
        from common.quaternion import q_mul  # the compiled product, loaded when first needed

        r = q_mul(q_mul(_Q_NED_ENU, q), _Q_FLU_FRD)
        return r if r[0] >= 0.0 else (-r[0], -r[1], -r[2], -r[3])
    aw = -h * x - h * y
    ax = h * w + h * z
    ay = h * w - h * z
    az = h * y - h * x
    if aw and ax and ay and az and math.isfinite(aw + ax + ay + az):
        return (-ax, aw, az, -ay) if ax <= 0.0 else (ax, -aw, -az, ay)
    # a = q_mul(_Q_NED_ENU, q), _Q_NED_ENU = (0, h, h, 0), every term written out
    aw = 0.0 * w - h * x - h * y - 0.0 * z
    ax = 0.0 * x + h * w + h * z - 0.0 * y
    ay = 0.0 * y - h * z + h * w + 0.0 * x
    az = 0.0 * z + h * y - h * x + 0.0 * w
    # q_mul(a, _Q_FLU_FRD), _Q_FLU_FRD = (0, 1, 0, 0)
    rw = aw * 0.0 - ax * 1.0 - ay * 0.0 - az * 0.0
    rx = aw * 1.0 + ax * 0.0 + ay * 0.0 - az * 0.0
    ry = aw * 0.0 - ax * 0.0 + ay * 0.0 + az * 1.0
    rz = aw * 0.0 + ax * 0.0 - ay * 1.0 + az * 0.0
    return (rw, rx, ry, rz) if rw >= 0.0 else (-rw, -rx, -ry, -rz)


def q_ned_frd_to_enu_flu(q: Quat) -> Quat:
    """Inverse of `q_enu_flu_to_ned_frd`, which is the same map (both fixed rotations are
    their own inverses up to sign), sign chosen with w >= 0."""
    return q_enu_flu_to_ned_frd(q)
