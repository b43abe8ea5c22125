"""Flight modes as PX4 numbers and names them: the FCU's HEARTBEAT says MAV_AUTOPILOT_PX4 and
carries PX4's custom mode, custom_mode = main_mode << 16 | sub_mode << 24, so pymavlink and
MAVProxy (`mavutil.mode_string_v10`), QGroundControl and MAVSDK show PX4's mode names and set
modes by them (MAV_CMD_DO_SET_MODE p1 = base mode with CUSTOM_MODE_ENABLED, p2 = main mode,
p3 = AUTO sub-mode; SET_MODE's custom_mode).

| mode     | PX4 main / sub mode    | pymavlink / MAVProxy | QGC      | MAVSDK           |
|----------|------------------------|----------------------|----------|------------------|
| HOLD     | AUTO (4) / LOITER (3)  | LOITER               | Hold     | HOLD             |
| MISSION  | AUTO (4) / MISSION (4) | MISSION              | Mission  | MISSION          |
| TAKEOFF  | AUTO (4) / TAKEOFF (2) | TAKEOFF              | Takeoff  | TAKEOFF          |
| LAND     | AUTO (4) / LAND (6)    | LAND                 | Land     | LAND             |
| RTL      | AUTO (4) / RTL (5)     | RTL                  | Return   | RETURN_TO_LAUNCH |
| POSCTL   | POSCTL (3)             | POSCTL               | Position | POSCTL           |
| OFFBOARD | OFFBOARD (6)           | OFFBOARD             | Offboard | OFFBOARD         |

HOLD is PX4's own name for AUTO.LOITER (its documentation's "Hold mode"); LOITER is accepted
everywhere a name is (`by_name`), as are QGC's Return and Position. Other PX4 modes (MANUAL,
ALTCTL, ACRO, STABILIZED, ...) are not flown here: `decode` returns None for them.
"""

from __future__ import annotations

from enum import Enum

# PX4 main modes and AUTO sub-modes (PX4's px4_custom_mode.h)
MAIN_MANUAL, MAIN_ALTCTL, MAIN_POSCTL, MAIN_AUTO, MAIN_ACRO, MAIN_OFFBOARD = 1, 2, 3, 4, 5, 6
MAIN_STABILIZED = 7
SUB_READY, SUB_TAKEOFF, SUB_LOITER, SUB_MISSION, SUB_RTL, SUB_LAND = 1, 2, 3, 4, 5, 6


class Mode(Enum):
    """The modes this FCU flies; value = (PX4 main mode, AUTO sub-mode or 0)."""

    HOLD = (MAIN_AUTO, SUB_LOITER)
    MISSION = (MAIN_AUTO, SUB_MISSION)
    OFFBOARD = (MAIN_OFFBOARD, 0)
    LAND = (MAIN_AUTO, SUB_LAND)
    TAKEOFF = (MAIN_AUTO, SUB_TAKEOFF)
    RTL = (MAIN_AUTO, SUB_RTL)
    POSCTL = (MAIN_POSCTL, 0)
    LOITER = (MAIN_AUTO, SUB_LOITER)  # an alias: Mode.LOITER is Mode.HOLD

    @property
    def custom_mode(self) -> int:
        main, sub = self.value
        return (main << 16) | (sub << 24)

    @property
    def px4_name(self) -> str:
        """The name pymavlink and MAVProxy give it (`mavutil.interpret_px4_mode`)."""
        return "LOITER" if self is Mode.HOLD else self.name


# Other names people use for the same modes (QGC's, MAVSDK's, PX4's internal ones).
ALIASES: dict[str, Mode] = {
    "AUTO.LOITER": Mode.HOLD, "RETURN": Mode.RTL, "RETURN_TO_LAUNCH": Mode.RTL,
    "AUTO.RTL": Mode.RTL, "POSITION": Mode.POSCTL, "AUTO.MISSION": Mode.MISSION,
    "AUTO.TAKEOFF": Mode.TAKEOFF, "AUTO.LAND": Mode.LAND,
}


def decode(main_mode: int, sub_mode: int) -> Mode | None:
    """The mode asked for by DO_SET_MODE p2/p3 (or SET_MODE's custom_mode), None if this FCU
    does not fly it. The sub-mode matters only under AUTO (PX4 ignores it elsewhere)."""
    for mode in Mode:
        main, sub = mode.value
        if main == main_mode and (main != MAIN_AUTO or sub == sub_mode):
            return mode
    return None


def decode_custom(custom_mode: int) -> Mode | None:
    return decode((custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF)


def by_name(name: str) -> Mode | None:
    """A mode by any of its names, case-insensitive: HOLD or LOITER, MISSION, TAKEOFF, LAND,
    RTL (RETURN), POSCTL (POSITION), OFFBOARD."""
    key = name.strip().upper()
    return Mode.__members__.get(key) or ALIASES.get(key)


def names() -> list[str]:
    """The modes' names (LOITER included); `by_name` also takes the ALIASES."""
    return list(Mode.__members__)
