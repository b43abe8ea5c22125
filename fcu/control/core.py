"""The FCU's control step without I/O: reference -> tracker -> wrench -> allocation.

The same `FlightCore` runs in the in-process runner, in the FCU process and in log replays;
time and dt come in as arguments, never from a clock. With lag compensation on (parameter
CA_LAG_COMP = 1, the FCU's default, put in force by fcu.params.apply_params) the allocation's
commands are led for the rotor lag and the tilt rate limit, from the reference's nominal
wrench (fcu.control.allocation.LagCompensator); off (a FlightCore built without it, as the control
law alone is flown in tests of eqs. 18-21), the step is the paper's plain allocation
(eqs. 28-29), bit for bit.

The step is one compiled kernel (`core_kernel`, numba): tracker, allocation and lead in one
call on the flat arrays the tracker, allocator and compensator keep their parameters and
state in (views of FlightCore's two buffers), so that Python runs once per period.
"""

from __future__ import annotations

import struct
from typing import NamedTuple

import numpy as np

from common.config.gains import Gains
from common.config.vehicle import VehicleConfig
from common.jit import compiled_for, njit
from common.vehicle_constants import N_ROTORS
from common.warm_ups import warm_up
from fcu.control import allocation as al
from fcu.control import tracker as tr
from fcu.control.allocation import AllocationResult, Allocator, LagCompensator, allocation_result
from fcu.control.layouts import (
    AO_SPEED,
    AO_TILT,
    CI_DT,
    CI_LAG_ON,
    CI_R,
    CI_SIZE,
    CI_X,
    CO_ALLOC,
    CO_SIZE,
    CO_TRACKER,
    CORE_PARAMS,
    CORE_STATE,
    CP_ALLOC,
    CP_LAG,
    CP_SIZE,
    CP_TRACKER,
    CS_INTEGRAL,
    CS_LAG,
    CS_SIZE,
    CS_TILT,
    K_G,
    K_J,
    K_MASS,
    R_A,
    R_Q,
    R_SIZE,
    R_W,
    R_WD,
    T_FORCE,
    T_WRENCH_END,
    X_Q,
    X_SIZE,
)
from fcu.control.tracker import DualQuaternionTracker, tracker_output
from fcu.envelope.feasibility import nominal_wrench_kernel
from fcu.stages import Reference, TrackerOutput, VehicleState

# The fused step's buffers (fcu.control.layouts): CORE_PARAMS holds the tracker's, the
# allocator's and the compensator's parameters; CORE_STATE the tracker's integral, the
# allocator's tilts and the compensator's state; CORE_IN the vehicle state, the reference,
# dt and lag compensation on (1) or off (0); CORE_OUT the tracker's output, then the
# allocation's (speeds and tilts led when lag compensation is on).
PARAMS_SIZE, STATE_SIZE, IN_SIZE, OUT_SIZE = CP_SIZE, CS_SIZE, CI_SIZE, CO_SIZE


@njit
def core_kernel(inp: np.ndarray, params: np.ndarray, state: np.ndarray,
                out: np.ndarray) -> None:
    """One control period on flat arrays (layouts above): eq. (16/33), eqs. (28-29), and the
    lead for the actuators' lag from the reference's nominal wrench when it is on."""
    x, r = inp[CI_X:CI_X + X_SIZE], inp[CI_R:CI_R + R_SIZE]
    dt_s = inp[CI_DT]
    k = params[CP_TRACKER:CP_ALLOC]
    tr.tracker_kernel(x, r, k, state[CS_INTEGRAL:CS_TILT], dt_s,
                      out[CO_TRACKER:CO_ALLOC])
    alloc = out[CO_ALLOC:CO_SIZE]
    al.allocate_kernel(params[CP_ALLOC:CP_LAG],
                       out[CO_TRACKER + T_FORCE:CO_TRACKER + T_WRENCH_END],
                       state[CS_TILT:CS_LAG], alloc)
    if inp[CI_LAG_ON] != 0.0:
        cp, cs = params[CP_LAG:CP_SIZE], state[CS_LAG:CS_SIZE]
        f, t = nominal_wrench_kernel(k[K_MASS], k[K_G], (k[K_J], k[K_J + 1], k[K_J + 2]),
                                     (r[R_Q], r[R_Q + 1], r[R_Q + 2], r[R_Q + 3]),
                                     (r[R_A], r[R_A + 1], r[R_A + 2]),
                                     (r[R_W], r[R_W + 1], r[R_W + 2]),
                                     (r[R_WD], r[R_WD + 1], r[R_WD + 2]))
        w6 = np.array((f[0], f[1], f[2], t[0], t[1], t[2]))
        w_lead, a_lead = np.empty(N_ROTORS), np.empty(N_ROTORS)
        al.lead_kernel(cp, cs, w6, dt_s, w_lead, a_lead)
        speeds, tilts = np.empty(N_ROTORS), np.empty(N_ROTORS)
        al.apply_kernel(cp, cs, alloc[AO_SPEED:AO_SPEED + N_ROTORS],
                        alloc[AO_TILT:AO_TILT + N_ROTORS], w_lead, a_lead, dt_s, speeds, tilts)
        alloc[AO_SPEED:AO_SPEED + N_ROTORS] = speeds
        alloc[AO_TILT:AO_TILT + N_ROTORS] = tilts


class StepResult(NamedTuple):
    reference: Reference
    tracker: TrackerOutput
    allocation: AllocationResult


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


_STATE_AND_REF = struct.Struct(f"={CI_DT - CI_X}d")  # CORE_IN's state and reference


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
        # the stages keep their parameters and state in the fused step's buffers
        params, state = self.params, self.state
        self.tracker.bind(CORE_PARAMS.view(params, "tracker"),
                          CORE_STATE.view(state, "integral"))
        self.allocator.bind(CORE_PARAMS.view(params, "allocator"),
                            CORE_STATE.view(state, "tilt_rad"))
        self.compensator.bind(CORE_PARAMS.view(params, "compensator"),
                              CORE_STATE.view(state, "compensator"))
        self.inp = np.zeros(IN_SIZE)
        self._inp_bytes = self.inp.data.cast("B")  # `step` packs into it
        self.out = np.zeros(OUT_SIZE)
        warm_up("fcu.control.core", self._warm_up)
        self._kernel = compiled_for(core_kernel, self.inp, params, state, self.out)

    def _warm_up(self) -> None:
        """The fused step once, on copies of the buffers, at identity with lag compensation
        (compiles or loads the kernels before the first control period)."""
        inp = np.zeros(IN_SIZE)
        inp[CI_X + X_Q] = inp[CI_R + R_Q] = 1.0  # q = q_d = identity
        inp[CI_DT], inp[CI_LAG_ON] = self.dt_s, 1.0
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
        inp[CI_DT] = dt_s
        inp[CI_LAG_ON] = 1.0 if self.lag_compensation else 0.0
        self._kernel(inp, self.params, self.state, self.out)
        return self.out

    def step(self, state: VehicleState, ref: Reference,
             dt_s: float | None = None) -> StepResult:
        """One control period of dt_s (default: the nominal period): desired wrench
        (eq. 16/33), then speeds and tilts (eq. 28-29), led for the actuators' lag when
        lag compensation is on."""
        # the control step's hot path: state and reference (CORE_IN's first two fields)
        # packed into the input buffer in one call, as float64 (numpy's conversion of a
        # sequence would cost twice as much)
        _STATE_AND_REF.pack_into(self._inp_bytes, 8 * CI_X, *state.p_enu_m, *state.q_enu_flu,
                                 *state.v_flu_m_s, *state.omega_flu_rad_s, *ref.p_enu_m,
                                 *ref.q_enu_flu, *ref.v_enu_m_s, *ref.a_enu_m_s2,
                                 *ref.omega_flu_rad_s, *ref.omega_dot_flu_rad_s2)
        out = self.step_arrays(self.dt_s if dt_s is None else float(dt_s)).tolist()
        return StepResult(ref, tracker_output(out[CO_TRACKER:CO_ALLOC]),
                          allocation_result(out[CO_ALLOC:CO_SIZE]))
