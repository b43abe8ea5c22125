"""Control allocation for tilt-rotors: geometry -> A (eq. 27) -> pseudo-inverse (eq. 28) ->
rotor speeds and tilts (eq. 29) -> unwrapped tilts (Algorithm 1, corrected; MODEL.md 2).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from common.config import VehicleConfig
from common.geometry import rotor_frames
from fcu.dualquat import Vec3, cross

TWO_PI = 2.0 * math.pi


def allocation_matrix(vehicle: VehicleConfig) -> np.ndarray:
    """The 6 x 2n static allocation matrix A: [f; tau] = A Omega, Omega = [lat_1, ver_1, ...]."""
    cf, cd = vehicle.thrust_coeff, vehicle.drag_coeff
    frames = rotor_frames(vehicle)
    a = np.zeros((6, 2 * len(frames)))
    for i, fr in enumerate(frames):
        for col, e in ((2 * i, fr.e_l_flu), (2 * i + 1, fr.e_v_flu)):
            moment = cross(fr.r_flu_m, e)
            a[:3, col] = [cf * c for c in e]
            a[3:, col] = [cf * moment[k] - fr.spin * cd * e[k] for k in range(3)]
    return a


def pseudo_inverse(a: np.ndarray) -> np.ndarray:
    """A^+ = A^T (A A^T)^-1 for a full-row-rank A (computed once)."""
    return a.T @ np.linalg.inv(a @ a.T)


def wrap_pi(x: float) -> float:
    """Wrap an angle to (-pi, pi]."""
    y = math.fmod(x + math.pi, TWO_PI)
    if y <= 0.0:
        y += TWO_PI
    return y - math.pi


class AllocationResult(NamedTuple):
    omega_sq: tuple[float, ...]  # Omega of eq. (28): lateral and vertical parts, per rotor
    speed_rad_s: tuple[float, ...]  # saturated to [0, w_max]
    tilt_raw_rad: tuple[float, ...]  # atan2 of eq. (29), in [-pi, pi]
    tilt_rad: tuple[float, ...]  # continuous tilt after unwrapping
    saturated: bool


class Allocator:
    """Pseudo-inverse allocation with speed saturation and corrected tilt unwrapping.

    The unwrapped tilt accumulates alpha*_t = alpha*_(t-1) + wrap(alpha_t - alpha*_(t-1)), which
    is continuous and equal to atan2 modulo 2 pi; below `hold_speed_rad_s` the thrust direction
    is undefined and the previous tilt is held.
    """

    def __init__(self, vehicle: VehicleConfig, initial_tilt_rad: tuple[float, ...] | None = None,
                 hold_speed_rad_s: float = 1.0) -> None:
        self.n = vehicle.n_rotors
        self.matrix = allocation_matrix(vehicle)
        self.pinv = pseudo_inverse(self.matrix)
        self._rows = tuple(tuple(float(x) for x in row) for row in self.pinv)
        self.speed_max = vehicle.rotor_speed_max_rad_s
        self.hold_speed = hold_speed_rad_s
        self.tilt: list[float] = list(initial_tilt_rad or (0.0,) * self.n)

    def reset(self, tilt_rad: tuple[float, ...]) -> None:
        self.tilt = list(tilt_rad)

    def solve(self, force_flu_n: Vec3, torque_flu_nm: Vec3) -> tuple[float, ...]:
        """Omega = A^+ [f; tau] (eq. 28), minimum-norm."""
        fx, fy, fz = force_flu_n
        tx, ty, tz = torque_flu_nm
        return tuple(a * fx + b * fy + c * fz + d * tx + e * ty + f * tz
                     for a, b, c, d, e, f in self._rows)

    def allocate(self, force_flu_n: Vec3, torque_flu_nm: Vec3) -> AllocationResult:
        """Rotor speeds and continuous tilts for a desired body wrench (eqs. 28-29)."""
        om = self.solve(force_flu_n, torque_flu_nm)
        speeds, raws = [], []
        tilt = self.tilt
        w_max, hold = self.speed_max, self.hold_speed
        saturated = False
        for i in range(self.n):
            lat, ver = om[2 * i], om[2 * i + 1]
            w = math.sqrt(math.sqrt(lat * lat + ver * ver))
            raw = math.atan2(lat, ver)
            raws.append(raw)
            if w > w_max:
                w = w_max
                saturated = True
            if w >= hold:
                tilt[i] += wrap_pi(raw - tilt[i])
            speeds.append(w)
        return AllocationResult(om, tuple(speeds), tuple(raws), tuple(tilt), saturated)


def hover_command(vehicle: VehicleConfig) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Rotor speeds and tilts that hold the vehicle level in hover (identity attitude)."""
    alloc = Allocator(vehicle)
    weight = vehicle.mass_kg * vehicle.gravity_m_s2
    result = alloc.allocate((0.0, 0.0, weight), (0.0, 0.0, 0.0))
    return result.speed_rad_s, result.tilt_rad
