"""Flight modes in PX4's custom-mode encoding, which MAVSDK uses for autopilots that are
neither PX4 nor ArduPilot: custom_mode = main_mode << 16 | sub_mode << 24."""

from __future__ import annotations

from enum import Enum

# PX4 main modes and AUTO sub-modes
MAIN_MANUAL, MAIN_ALTCTL, MAIN_POSCTL, MAIN_AUTO, MAIN_ACRO, MAIN_OFFBOARD = 1, 2, 3, 4, 5, 6
MAIN_STABILIZED = 7
SUB_READY, SUB_TAKEOFF, SUB_LOITER, SUB_MISSION, SUB_RTL, SUB_LAND = 1, 2, 3, 4, 5, 6


class Mode(Enum):
    """The modes this FCU flies; value = (main mode, AUTO sub-mode)."""

    HOLD = (MAIN_AUTO, SUB_LOITER)
    MISSION = (MAIN_AUTO, SUB_MISSION)
    OFFBOARD = (MAIN_OFFBOARD, 0)
    LAND = (MAIN_AUTO, SUB_LAND)

    @property
    def custom_mode(self) -> int:
        main, sub = self.value
        return (main << 16) | (sub << 24)


def decode(main_mode: int, sub_mode: int) -> Mode | None:
    """The mode asked for by DO_SET_MODE p2/p3 (or SET_MODE's custom_mode), None if unknown.

    POSCTL is taken as HOLD (position hold is what this vehicle does without a pilot).
    """
    if main_mode == MAIN_POSCTL:
        return Mode.HOLD
    for mode in Mode:
        main, sub = mode.value
        if main == main_mode and (main != MAIN_AUTO or sub == sub_mode):
            return mode
    return None


def decode_custom(custom_mode: int) -> Mode | None:
    return decode((custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF)


def by_name(name: str) -> Mode | None:
    return Mode.__members__.get(name.upper())
