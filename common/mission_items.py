"""Mission items as MISSION_ITEM_INT carries them (local frames: x, y in 1e-4 m)."""

from __future__ import annotations

from typing import NamedTuple

LOCAL_SCALE = 1e4  # MISSION_ITEM_INT x, y in local frames: metres x 1e4


class MissionItem(NamedTuple):
    seq: int
    frame: int
    command: int
    current: int
    autocontinue: int
    param1: float
    param2: float
    param3: float
    param4: float
    x: int
    y: int
    z: float
    mission_type: int = 0

    @property
    def x_m(self) -> float:
        return self.x / LOCAL_SCALE

    @property
    def y_m(self) -> float:
        return self.y / LOCAL_SCALE

    def with_seq(self, seq: int) -> MissionItem:
        return self._replace(seq=seq)


def local_xy(metres: float) -> int:
    """Metres to the int32 of MISSION_ITEM_INT in a local frame."""
    return round(metres * LOCAL_SCALE)
