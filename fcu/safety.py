"""The output stage the controller cannot bypass (cf. Crazyflie's supervisor): zero rotor
speed unless armed, and never a non-finite value on the wire."""

from __future__ import annotations

import math
from typing import NamedTuple


class GateOutput(NamedTuple):
    speed_rad_s: tuple[float, ...]
    tilt_rad: tuple[float, ...]
    fault: str  # empty when the command passed


def gate(armed: bool, speed_rad_s: tuple[float, ...], tilt_rad: tuple[float, ...],
         held_tilt_rad: tuple[float, ...]) -> GateOutput:
    """Pass an armed, finite command; otherwise zero speeds and the last finite tilts.

    A non-finite command is a fault: the caller disarms and reports it.
    """
    zero = (0.0,) * len(speed_rad_s)
    finite = all(math.isfinite(x) for x in speed_rad_s) and all(
        math.isfinite(x) for x in tilt_rad)
    if not finite:
        return GateOutput(zero, held_tilt_rad, "non-finite actuator command")
    if not armed:
        return GateOutput(zero, tilt_rad, "")
    return GateOutput(speed_rad_s, tilt_rad, "")
