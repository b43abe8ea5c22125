"""POSCTL's state: the latest sticks (MANUAL_CONTROL, judged fresh on the wall clock), the
set-point they move (`fcu.modes.manual`), the limits fitted to the vehicle and a fit under
way; pure, no I/O."""

from __future__ import annotations

import math

from fcu.control.dualquat import Vec3
from fcu.mission.start import PosctlFit
from fcu.modes import manual
from fcu.modes.manual import ManualSetpoint, Sticks, StickSettings
from fcu.stages import Reference, pose_ref


class Posctl:
    """POSCTL's sticks, set-point (`sp`; None: it starts from where the vehicle should be),
    its limits fitted to the vehicle, and their fit under way (`fit`)."""

    def __init__(self, limits: StickSettings) -> None:
        self.sticks = manual.CENTRED  # the latest MANUAL_CONTROL
        self.received_s = -math.inf  # wall clock; -inf: never
        self.sp: ManualSetpoint | None = None
        self.limits = limits  # fitted to the vehicle (`manual.fit_envelope`)
        self.fit: PosctlFit | None = None  # the limits being fitted

    def take(self, now_s: float, sticks: Sticks) -> None:
        """The sticks of a MANUAL_CONTROL received at `now_s` (wall clock)."""
        self.sticks = sticks
        self.received_s = now_s

    def fresh(self, now_s: float, timeout_s: float) -> bool:
        """MANUAL_CONTROL heard within `timeout_s` (COM_RC_LOSS_T, wall clock)."""
        return now_s - self.received_s <= timeout_s

    def restart(self) -> None:
        """The set-point starts again from where the vehicle should be (POSCTL entered,
        arming, new stick limits)."""
        self.sp = None

    def step(self, t_us: int, here: Reference | None, p_vehicle: Vec3 | None) -> Reference:
        """The set-point moved as the sticks say at `t_us`, from `here` (the reference flown,
        or where the vehicle should be; given when `sp` is None: `manual.start`); held still
        at its pose while its limits are being fitted."""
        sp = self.sp
        if sp is None:
            assert here is not None
            if self.fit is not None:  # its limits being fitted: hold still till then
                return pose_ref(here.p_enu_m, here.q_enu_flu)
            sp = manual.continuing(t_us, here)
        self.sp, ref = manual.advance(sp, t_us, self.sticks, self.limits, p_vehicle)
        return ref
