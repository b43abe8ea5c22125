"""Failsafe checks, each in one place (parameters COM_*, as PX4's commander names them).

Pure: every check takes its clock as an argument. The flight clock (`t_us`: simulated time
in lockstep, monotonic time in real time) drives what changes the flight: state input loss,
saturation, divergence. The wall clock (`now_s`) serves only the links: GCS heartbeat loss,
the offboard setpoint stream and MANUAL_CONTROL (docs/clocks.md). In lockstep a state
arrives with every control period, so state input loss cannot happen on the flight clock:
a simulator that stops answering freezes the flight with it and is reported by the process
shell.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum, IntEnum, StrEnum

from common.outcome import DIVERGENCE_M


class Failsafe(StrEnum):
    """The failsafe in force (`Pipeline.failsafe`), its value what the logs and STATUSTEXTs
    name; NONE (empty, false) when none is."""

    NONE = ""
    STATE_LOST = "state input lost"
    DIVERGED = "diverged"
    NON_FINITE = "non-finite command"
    ESTIMATOR_FAILED = "estimator failed"
    ESTIMATOR_INCONSISTENT = "estimator inconsistent"
    POSE_LOST = "pose source lost"
    ROTOR_SATURATION = "rotor saturation"
    GCS_LOST = "GCS link lost"


class PoseLoss(IntEnum):
    """How long the pose source has been lost (`pose_loss_level`): FRESH (or dead-reckoning
    within COM_POS_LOSS_T), then HOLD, then LAND (COM_POS_LAND_T later)."""

    FRESH = 0
    HOLD = 1
    LAND = 2


class SaturationChange(Enum):
    """What `SaturationMonitor.update` saw: NONE, START (held longer than COM_SAT_T), CLEAR."""

    NONE = "none"
    START = "start"
    CLEAR = "clear"


class LinkChange(Enum):
    """What `GcsLinkMonitor.update` saw: NONE, LOST (COM_DL_LOSS_T), LAND (COM_DL_LAND_T
    more), REGAINED."""

    NONE = "none"
    LOST = "lost"
    LAND = "land"
    REGAINED = "regained"


# the failsafes logged as PX4's failsafe_flags.fd_critical_failure (the vehicle lost, not a
# degraded flight: the onboard log)
CRITICAL_FAILSAFES = (Failsafe.DIVERGED, Failsafe.NON_FINITE)


@dataclass(frozen=True)
class FailsafeSettings:
    """Failsafe parameters; times in seconds."""

    gcs_loss_s: float = 0.0  # COM_DL_LOSS_T, wall clock; 0: off
    gcs_loss_land_s: float = 0.0  # COM_DL_LAND_T, wall clock; 0: hold forever
    state_loss_s: float = 1.0  # COM_STATE_LOSS_T, flight clock
    saturation_s: float = 2.0  # COM_SAT_T, flight clock
    saturation_hold: bool = False  # COM_SAT_ACT = 1: abort a mission to HOLD
    actuator_limit_s: float = 0.1  # COM_ACT_RATE_T: an actuator limited this long is reported
    divergence_m: float = DIVERGENCE_M  # COM_DIV_POS
    pose_loss_s: float = 1.0  # COM_POS_LOSS_T: dead-reckon this long without a pose, then HOLD
    pose_loss_land_s: float = 2.0  # COM_POS_LAND_T: then LAND after this long in HOLD
    gate_failures: int = 20  # EKF_GATE_N: poses refused by the gate in a row: inconsistent


def state_lost(t_us: int, state_rx_us: int | None, settings: FailsafeSettings) -> bool:
    """No valid state for longer than COM_STATE_LOSS_T on the flight clock."""
    if state_rx_us is None:
        return False
    return (t_us - state_rx_us) * 1e-6 > settings.state_loss_s


def pose_loss_level(t_us: int, last_fusion_us: int, settings: FailsafeSettings) -> PoseLoss:
    """FRESH: the pose source is fresh (or dead-reckoning within COM_POS_LOSS_T), HOLD, then
    LAND (COM_POS_LAND_T later); on the flight clock, from the last fused capture."""
    if last_fusion_us < 0:
        return PoseLoss.FRESH
    age_s = (t_us - last_fusion_us) * 1e-6
    if age_s > settings.pose_loss_s + settings.pose_loss_land_s:
        return PoseLoss.LAND
    return PoseLoss.HOLD if age_s > settings.pose_loss_s else PoseLoss.FRESH


def offboard_lost(now_s: float, received_s: float, timeout_s: float) -> bool:
    """No offboard setpoint for longer than COM_OF_LOSS_T on the wall clock."""
    return now_s - received_s > timeout_s


def manual_control_lost(now_s: float, received_s: float, timeout_s: float) -> bool:
    """No MANUAL_CONTROL for longer than COM_RC_LOSS_T on the wall clock (PX4's RC loss; the
    reaction here is HOLD, PX4's NAV_RCL_ACT = 1)."""
    return now_s - received_s > timeout_s


class SaturationMonitor:
    """Rotor speed saturation held longer than COM_SAT_T (flight clock)."""

    def __init__(self) -> None:
        self.since_us: int | None = None
        self.reported = False

    def update(self, t_us: int, saturated: bool,
               settings: FailsafeSettings) -> SaturationChange:
        """START once the saturation has lasted too long, CLEAR when it ends, else NONE."""
        if not saturated:
            self.since_us = None
            was = self.reported
            self.reported = False
            return SaturationChange.CLEAR if was else SaturationChange.NONE
        if self.since_us is None:
            self.since_us = t_us
        if not self.reported and (t_us - self.since_us) * 1e-6 > settings.saturation_s:
            self.reported = True
            return SaturationChange.START
        return SaturationChange.NONE


class GcsLinkMonitor:
    """GCS heartbeat loss (wall clock): HOLD after COM_DL_LOSS_T, LAND after COM_DL_LAND_T
    more, REGAINED when heartbeats come back."""

    def __init__(self) -> None:
        self.lost_since_s: float | None = None
        self.landing_ordered = False

    def update(self, now_s: float, gcs_seen_s: float,
               settings: FailsafeSettings) -> LinkChange:
        """LOST, LAND, REGAINED or NONE."""
        if settings.gcs_loss_s <= 0.0 or not math.isfinite(gcs_seen_s):
            return LinkChange.NONE
        lost = now_s - gcs_seen_s > settings.gcs_loss_s
        if lost and self.lost_since_s is None:
            self.lost_since_s = now_s
            self.landing_ordered = False
            return LinkChange.LOST
        if lost and not self.landing_ordered and settings.gcs_loss_land_s > 0.0 and \
                self.lost_since_s is not None and \
                now_s - self.lost_since_s > settings.gcs_loss_land_s:
            self.landing_ordered = True
            return LinkChange.LAND
        if not lost and self.lost_since_s is not None:
            self.lost_since_s = None
            return LinkChange.REGAINED
        return LinkChange.NONE
