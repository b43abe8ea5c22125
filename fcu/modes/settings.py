"""The automatic modes' and POSCTL's parameters (PX4's names)."""

from __future__ import annotations

from dataclasses import dataclass, field

from fcu.modes.manual import StickSettings


@dataclass(frozen=True)
class FlightSettings:
    """The automatic modes' and POSCTL's parameters (PX4's names)."""

    takeoff_alt_m: float = 2.5  # MIS_TAKEOFF_ALT: TAKEOFF climbs this much
    rtl_return_alt_m: float = 10.0  # RTL_RETURN_ALT: RTL climbs to this height above home
    rtl_cruise_m_s: float = 5.0  # MPC_XY_CRUISE: RTL's travel top speed
    manual_timeout_s: float = 0.5  # COM_RC_LOSS_T: POSCTL without MANUAL_CONTROL -> HOLD
    sticks: StickSettings = field(default_factory=StickSettings)
