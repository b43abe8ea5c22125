"""The FCU's control step without I/O: reference -> tracker -> wrench -> allocation.

The same `FlightCore` runs in the in-process runner, in the FCU process and in log replays;
time and dt come in as arguments, never from a clock.
"""

from __future__ import annotations

from typing import NamedTuple

from common.config import Gains, VehicleConfig
from fcu.allocation import AllocationResult, Allocator
from fcu.tracker import DualQuaternionTracker, Reference, TrackerOutput, VehicleState


class StepResult(NamedTuple):
    reference: Reference
    tracker: TrackerOutput
    allocation: AllocationResult


class FlightCore:
    def __init__(self, vehicle: VehicleConfig, gains: Gains, control_rate_hz: int,
                 initial_tilt_rad: tuple[float, ...] | None = None) -> None:
        self.vehicle = vehicle
        self.dt_s = 1.0 / control_rate_hz
        self.tracker = DualQuaternionTracker(vehicle, gains)
        self.allocator = Allocator(vehicle, initial_tilt_rad)

    def step(self, state: VehicleState, ref: Reference) -> StepResult:
        """One control period: desired wrench (eq. 16/33) then speeds and tilts (eq. 28-29)."""
        out = self.tracker.update(state, ref, self.dt_s)
        alloc = self.allocator.allocate(out.force_flu_n, out.torque_flu_nm)
        return StepResult(ref, out, alloc)
