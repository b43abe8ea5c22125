"""What a mission may ask for: `MissionLimits` (the MIS_* and GF_* parameters)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from common.config.scenario import VehicleConfig


@dataclass(frozen=True)
class MissionLimits:
    """What a mission may ask for, and the speeds of the items that have no duration.

    `vehicle`: the airframe whose actuator envelope missions must respect (items stretched
    or refused, `fcu.mission` docstring); None skips that check."""

    max_items: int = 500
    max_distance_m: float = 1000.0  # geofence: radius around the origin
    cruise_speed_m_s: float = 2.0
    land_speed_m_s: float = 0.5
    takeoff_speed_m_s: float = 1.0
    turn_rate_deg_s: float = 30.0  # yaw changes of speed-timed items take at least this long
    item_max_s: float = 600.0  # the longest item duration a refusal's hint may propose
    vehicle: VehicleConfig | None = None

    def __post_init__(self) -> None:
        for name in ("max_distance_m", "cruise_speed_m_s", "land_speed_m_s",
                     "takeoff_speed_m_s", "turn_rate_deg_s", "item_max_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"MissionLimits.{name} must be finite and > 0, got {value}")
        if self.max_items < 0:
            raise ValueError(f"MissionLimits.max_items must be >= 0, got {self.max_items}")
