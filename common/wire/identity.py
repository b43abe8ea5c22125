"""How this project's FCU tells a ground station what it flies, beside the HEARTBEAT that
says MAV_AUTOPILOT_PX4 (so that MAVSDK, MAVProxy and QGroundControl treat it as PX4).

PX4 and ArduPilot fly a position target or an attitude target, never both at once: in PX4's
OFFBOARD each SET_ATTITUDE_TARGET turns position control off, and in ArduPilot's GUIDED it
replaces the position target. This FCU flies the two together (a 6-DoF pose: the tilt rotors
hold any attitude at any position). It says so in AUTOPILOT_VERSION.flight_custom_version,
the 8 bytes PX4 fills with the first bytes of its git hash: this FCU sends the ASCII bytes
`dqflight` there. A ground station that reads them sends attitude targets beside the
position; to any other vehicle `gcs goto` sends the position and the yaw alone, and refuses
a roll or a pitch.
"""

from __future__ import annotations

from collections.abc import Sequence

FLIGHT_CUSTOM_VERSION = b"dqflight"


def flies_pose(flight_custom_version: Sequence[int] | bytes | None) -> bool:
    """Whether an AUTOPILOT_VERSION's flight_custom_version says "flies position and
    attitude together" (this FCU's tag); False for None (no AUTOPILOT_VERSION heard)."""
    if flight_custom_version is None:
        return False
    return bytes(bytearray(flight_custom_version)) == FLIGHT_CUSTOM_VERSION
