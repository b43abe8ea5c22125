"""The supervisor: the one output gate between the allocator and the actuators, which the
controller cannot bypass (Crazyflie's `supervisorAreMotorsAllowedToRun`).

Rotor speeds pass only while armed, clamped to [0, w_max]; disarmed, they are zero and the
tilts given pass (the pipeline gives the allocator's last ones, so the servos do not move on
the ground). A command that is not finite is a fault: zero speeds, the last finite tilts, and
the pipeline disarms. Failsafes and the actuator monitor are the pipeline's checks, not this
gate's (docs/architecture.md#the-fcus-pipeline).
"""

from __future__ import annotations

import math
from typing import NamedTuple


class GateOutput(NamedTuple):
    speed_rad_s: tuple[float, ...]
    tilt_rad: tuple[float, ...]
    fault: str  # empty when the command passed


class Supervisor:
    def __init__(self, n_rotors: int, speed_max_rad_s: float,
                 initial_tilt_rad: tuple[float, ...] | None = None) -> None:
        self.zero = (0.0,) * n_rotors
        self.speed_max = speed_max_rad_s
        self.held_tilt: tuple[float, ...] = tuple(initial_tilt_rad or self.zero)

    def gate(self, armed: bool, speed_rad_s: tuple[float, ...],
             tilt_rad: tuple[float, ...]) -> GateOutput:
        """What reaches the actuators for a command and the arming state."""
        # a finite sum: all finite; else (NaN, inf, overflow) each one
        finite = math.isfinite(sum(speed_rad_s) + sum(tilt_rad)) or (
            all(map(math.isfinite, speed_rad_s)) and all(map(math.isfinite, tilt_rad)))
        if not finite:
            return GateOutput(self.zero, self.held_tilt, "non-finite actuator command")
        self.held_tilt = tuple(tilt_rad)
        if not armed:
            return GateOutput(self.zero, self.held_tilt, "")
        w_max = self.speed_max
        speeds = tuple([0.0 if w < 0.0 else (w_max if w > w_max else w) for w in speed_rad_s])
        return GateOutput(speeds, self.held_tilt, "")
