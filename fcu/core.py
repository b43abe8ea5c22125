"""The FCU's control step without I/O: reference -> tracker -> wrench -> allocation.

The same `FlightCore` runs in the in-process runner, in the FCU process and in log replays;
time and dt come in as arguments, never from a clock. With lag compensation on (parameter
CA_LAG_COMP = 1, the FCU's default, put in force by fcu.params.apply_params) the allocation's
commands are led for the rotor lag and the tilt rate limit, from the reference's nominal
wrench (fcu.allocation.LagCompensator); off (a FlightCore built without it, as the control
law alone is flown in tests of eqs. 18-21), the step is the paper's plain allocation
(eqs. 28-29), bit for bit.

The step is one compiled kernel (`core_kernel`, numba): tracker, allocation and lead in one
call on the flat arrays the tracker, allocator and compensator keep their parameters and
state in (views of FlightCore's two buffers), so that Python runs once per period.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from common.config import Gains, VehicleConfig
from common.jit import njit, warm_up
from fcu import allocation as al
from fcu import tracker as tr
from fcu.allocation import AllocationResult, Allocator, LagCompensator, allocation_result
from fcu.feasibility import nominal_wrench_kernel
from fcu.tracker import (
    DualQuaternionTracker,
    Reference,
    TrackerOutput,
    VehicleState,
    tracker_output,
)

# The fused step's buffers. params: the tracker's, the allocator's, the compensator's;
# state: the tracker's integral, the allocator's tilts, the compensator's state.
_P_TR, _P_AL = 0, tr.PARAMS_SIZE
_P_LAG = _P_AL + al.ALLOC_PARAMS_SIZE
PARAMS_SIZE = _P_LAG + al.LAG_PARAMS_SIZE
_S_TILT, _S_LAG = 6, 12
STATE_SIZE = _S_LAG + al.LAG_STATE_SIZE
# input: state (13), reference (19), dt, lag compensation on (1) or off (0)
IN_SIZE = tr.STATE_SIZE + tr.REF_SIZE + 2
# output: the tracker's (24), then the allocation's (31): Omega, speeds, raw tilts, tilts,
# saturated (speeds and tilts led when lag compensation is on)
OUT_SIZE = tr.OUT_SIZE + al.ALLOC_OUT_SIZE


@njit
def core_kernel(inp: np.ndarray, params: np.ndarray, state: np.ndarray,
                out: np.ndarray) -> None:
    """One control period on flat arrays (layouts above): eq. (16/33), eqs. (28-29), and the
    lead for the actuators' lag from the reference's nominal wrench when it is on."""
    x, r = inp[0:13], inp[13:32]
    dt_s = inp[32]
    k = params[_P_TR:_P_AL]
    tr.tracker_kernel(x, r, k, state[0:_S_TILT], dt_s, out[0:24])
    alloc = out[24:55]
    al.allocate_kernel(params[_P_AL:_P_LAG], out[0:6], state[_S_TILT:_S_LAG], alloc)
    if inp[33] != 0.0:
        cp, cs = params[_P_LAG:PARAMS_SIZE], state[_S_LAG:STATE_SIZE]
        f, t = nominal_wrench_kernel(k[18], k[22], (k[19], k[20], k[21]),
                                     (r[3], r[4], r[5], r[6]), (r[10], r[11], r[12]),
                                     (r[13], r[14], r[15]), (r[16], r[17], r[18]))
        w6 = np.array((f[0], f[1], f[2], t[0], t[1], t[2]))
        w_lead, a_lead = np.empty(al.N_ROTORS), np.empty(al.N_ROTORS)
        al.lead_kernel(cp, cs, w6, dt_s, w_lead, a_lead)
        speeds, tilts = np.empty(al.N_ROTORS), np.empty(al.N_ROTORS)
        al.apply_kernel(cp, cs, alloc[12:18], alloc[24:30], w_lead, a_lead, dt_s, speeds,
                        tilts)
        alloc[12:18] = speeds
        alloc[24:30] = tilts


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
        self.params = np.zeros(PARAMS_SIZE)
        self.state = np.zeros(STATE_SIZE)
        self.tracker.bind(self.params[_P_TR:_P_AL], self.state[0:_S_TILT])
        self.allocator.bind(self.params[_P_AL:_P_LAG], self.state[_S_TILT:_S_LAG])
        self.compensator.bind(self.params[_P_LAG:PARAMS_SIZE], self.state[_S_LAG:STATE_SIZE])
        self.inp = np.zeros(IN_SIZE)
        self.out = np.zeros(OUT_SIZE)
        warm_up("fcu.core", self._warm_up)

    def _warm_up(self) -> None:
        """The fused step once, on copies of the buffers, at identity with lag compensation
        (compiles or loads the kernels before the first control period)."""
        inp = np.zeros(IN_SIZE)
        inp[3] = inp[16] = 1.0  # q = q_d = identity
        inp[32], inp[33] = self.dt_s, 1.0
        core_kernel(inp, self.params.copy(), self.state.copy(), np.zeros(OUT_SIZE))

    def set_lag_compensation(self, on: bool) -> None:
        """CA_LAG_COMP: lead the commands for the actuators' lag (on) or not; switching on
        starts afresh (the first period after it is not led)."""
        if on and not self.lag_compensation:
            self.compensator.reset()
        self.lag_compensation = on

    def step_arrays(self, dt_s: float) -> np.ndarray:
        """The step on `self.inp` (state and reference filled in by the caller; dt and the
        lag switch are set here): returns `self.out` (OUT_SIZE), overwritten next step."""
        inp = self.inp
        inp[32] = dt_s
        inp[33] = 1.0 if self.lag_compensation else 0.0
        core_kernel(inp, self.params, self.state, self.out)
        return self.out

    def step(self, state: VehicleState, ref: Reference,
             dt_s: float | None = None) -> StepResult:
        """One control period of dt_s (default: the nominal period): desired wrench
        (eq. 16/33), then speeds and tilts (eq. 28-29), led for the actuators' lag when
        lag compensation is on."""
        self.inp[0:32] = (*state.p_enu_m, *state.q_enu_flu, *state.v_flu_m_s,
                          *state.omega_flu_rad_s, *ref.p_enu_m, *ref.q_enu_flu, *ref.v_enu_m_s,
                          *ref.a_enu_m_s2, *ref.omega_flu_rad_s, *ref.omega_dot_flu_rad_s2)
        out = self.step_arrays(self.dt_s if dt_s is None else float(dt_s)).tolist()
        return StepResult(ref, tracker_output(out), allocation_result(out[24:55]))
