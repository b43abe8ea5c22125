"""Rotor geometry of a tilt-rotor multirotor (docs/model.md#geometry), body frame FLU.

Arm i is rotated by Rz(gamma_i) Ry(beta_i); the rotor tilts about its arm axis a_i, and its
thrust direction is n_i = cos(alpha_i) e_v,i + sin(alpha_i) e_l,i.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from common.config.vehicle import VehicleConfig

Vec3 = tuple[float, float, float]


class RotorFrame(NamedTuple):
    """Unit vectors and position of one rotor in FLU; `spin` +1 = counter-clockwise."""

    r_flu_m: Vec3  # rotor position l a_i
    arm_flu: Vec3  # a_i, outward arm axis = tilt axis
    e_v_flu: Vec3  # thrust direction at alpha = 0
    e_l_flu: Vec3  # thrust direction at alpha = +pi/2
    spin: int


def rotor_frames(vehicle: VehicleConfig) -> tuple[RotorFrame, ...]:
    frames = []
    for gamma, beta, spin in zip(vehicle.arm_azimuth_rad, vehicle.arm_elevation_rad,
                                 vehicle.spin, strict=True):
        cg, sg, cb, sb = math.cos(gamma), math.sin(gamma), math.cos(beta), math.sin(beta)
        arm = (cb * cg, cb * sg, -sb)
        e_v = (sb * cg, sb * sg, cb)
        e_l = (sg, -cg, 0.0)
        length = vehicle.arm_length_m
        r = (length * arm[0], length * arm[1], length * arm[2])
        frames.append(RotorFrame(r, arm, e_v, e_l, spin))
    return tuple(frames)
