"""The FCU's control step without I/O: reference -> tracker -> wrench -> allocation.

The same `FlightCore` runs in the in-process runner, in the FCU process and in log replays;
time and dt come in as arguments, never from a clock. With lag compensation on (parameter
CA_LAG_COMP = 1, the FCU's default, put in force by fcu.params.apply_params) the allocation's
commands are led for the rotor lag and the tilt rate limit, from the reference's nominal
wrench (fcu.allocation.LagCompensator); off (a FlightCore built without it, as the control
law alone is flown in tests of eqs. 18-21), the step is the paper's plain allocation
(eqs. 28-29), bit for bit.
"""

from __future__ import annotations

from typing import NamedTuple

from common.config import Gains, VehicleConfig
from fcu.allocation import AllocationResult, Allocator, LagCompensator
from fcu.feasibility import nominal_wrench
from fcu.tracker import DualQuaternionTracker, Reference, TrackerOutput, VehicleState


class StepResult(NamedTuple):
    reference: Reference
    tracker: TrackerOutput
    allocation: AllocationResult


ONBOARD_COLUMNS = (
    "time_us", "px", "py", "pz", "qw", "qx", "qy", "qz", "vbx", "vby", "vbz", "wx", "wy", "wz",
    "pdx", "pdy", "pdz", "qdw", "qdx", "qdy", "qdz", "vdx", "vdy", "vdz", "wdx", "wdy", "wdz",
    "fx", "fy", "fz", "tx", "ty", "tz",
    *(f"rotor_cmd{i}" for i in range(6)), *(f"tilt_cmd{i}" for i in range(6)),
    *(f"tilt_raw{i}" for i in range(6)), "saturated", "armed", "step_us",
    # ln q_hat_e = 1/2 (theta_e n_e + eps p_e) (eq. 16) and the twist error xi_e (eq. 11)
    "lnqe_rx", "lnqe_ry", "lnqe_rz", "lnqe_dx", "lnqe_dy", "lnqe_dz",
    "xie_rx", "xie_ry", "xie_rz", "xie_dx", "xie_dy", "xie_dz")


def onboard_row(time_us: int, state: VehicleState, result: StepResult,
                speed_cmd: tuple[float, ...], tilt_cmd: tuple[float, ...], armed: bool,
                step_us: float) -> tuple[float, ...]:
    """One row of the onboard log (ONBOARD_COLUMNS): what the FCU saw, wanted and sent."""
    ref, out, alloc = result
    return (time_us, *state.p_enu_m, *state.q_enu_flu, *state.v_flu_m_s,
            *state.omega_flu_rad_s, *ref.p_enu_m, *ref.q_enu_flu, *ref.v_enu_m_s,
            *ref.omega_flu_rad_s, *out.force_flu_n, *out.torque_flu_nm, *speed_cmd, *tilt_cmd,
            *alloc.tilt_raw_rad, float(alloc.saturated), float(armed), step_us,
            *out.log_error, *out.twist_error)


class _Tracker(DualQuaternionTracker):
    """The tracker, whose reset (at arming) also restarts the allocation's lag compensator
    (its rotor model would otherwise start from the last flight's speeds)."""

    def __init__(self, vehicle: VehicleConfig, gains: Gains, compensator: LagCompensator
                 ) -> None:
        super().__init__(vehicle, gains)
        self._compensator = compensator

    def reset(self) -> None:
        super().reset()
        self._compensator.reset()


class FlightCore:
    def __init__(self, vehicle: VehicleConfig, gains: Gains, control_rate_hz: int,
                 initial_tilt_rad: tuple[float, ...] | None = None, *,
                 lag_compensation: bool = False) -> None:
        self.vehicle = vehicle
        self.dt_s = 1.0 / control_rate_hz
        self.allocator = Allocator(vehicle, initial_tilt_rad)
        self.compensator = LagCompensator(vehicle, self.allocator.hold_speed)
        self.tracker: DualQuaternionTracker = _Tracker(vehicle, gains, self.compensator)
        self.lag_compensation = lag_compensation

    def set_lag_compensation(self, on: bool) -> None:
        """CA_LAG_COMP: lead the commands for the actuators' lag (on) or not; switching on
        starts afresh (the first period after it is not led)."""
        if on and not self.lag_compensation:
            self.compensator.reset()
        self.lag_compensation = on

    def step(self, state: VehicleState, ref: Reference,
             dt_s: float | None = None) -> StepResult:
        """One control period of dt_s (default: the nominal period): desired wrench
        (eq. 16/33), then speeds and tilts (eq. 28-29), led for the actuators' lag when
        lag compensation is on."""
        dt = self.dt_s if dt_s is None else dt_s
        out = self.tracker.update(state, ref, dt)
        alloc = self.allocator.allocate(out.force_flu_n, out.torque_flu_nm)
        if self.lag_compensation:
            comp = self.compensator
            alloc = comp.apply(alloc, *comp.lead(*nominal_wrench(self.vehicle, ref), dt), dt)
        return StepResult(ref, out, alloc)
