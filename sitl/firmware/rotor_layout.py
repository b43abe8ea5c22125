"""Which of the vehicle's rotors sits under each motor output of a firmware's planar
multirotor layout (ArduCopter's and PX4's hexa X): pure, no I/O."""

from __future__ import annotations

import math
from collections.abc import Sequence

from common.config.scenario import ConfigError, VehicleConfig

ANGLE_TOL_DEG = 1.0


def _wrap_deg(a: float) -> float:
    return (a + 180.0) % 360.0 - 180.0


def _turning(spin: int) -> str:
    return "counter-clockwise" if spin > 0 else "clockwise"


def rotors_for_outputs(vehicle: VehicleConfig, layout: Sequence[tuple[float, int]],
                       frame: str, hint: str = "") -> tuple[int, ...]:
    """The vehicle's rotor for each output k of `layout`, (arm angle in degrees clockwise
    from forward seen from above, propeller spin seen from above: +1 counter-clockwise):
    the rotor at that arm angle, which must lie in the body's plane and spin the same way;
    ConfigError naming the first output whose rotor does not (`frame` names the layout,
    `hint` ends the spin message)."""
    out = []
    for k, (angle_deg, spin) in enumerate(layout, start=1):
        # clockwise from forward seen from above = -azimuth in FLU (anticlockwise from +x)
        match = [i for i, az in enumerate(vehicle.arm_azimuth_rad)
                 if abs(_wrap_deg(math.degrees(az) + angle_deg)) <= ANGLE_TOL_DEG]
        if len(match) != 1:
            raise ConfigError(f"vehicle {vehicle.name}: no rotor at {frame} motor {k} (arm "
                              f"{angle_deg:g} deg clockwise from forward)")
        i = match[0]
        if abs(vehicle.arm_elevation_rad[i]) > 1e-9:
            raise ConfigError(f"vehicle {vehicle.name}: rotor {i} ({frame} motor {k}) is "
                              f"tilted out of the body plane: {frame} is planar")
        if vehicle.spin[i] != spin:
            raise ConfigError(
                f"vehicle {vehicle.name}: rotor {i} spins {_turning(vehicle.spin[i])}, {frame} "
                f"motor {k} there spins {_turning(spin)} (its yaw control would run "
                f"backwards){hint}")
        out.append(i)
    return tuple(out)
