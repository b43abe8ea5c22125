"""What every mission file format shares: the error, the document (items and the home it
names), and MISSION_ITEM_INT's fields as the files write them (range checks, shortest
round-trip floats, x and y in the frame's unit a quarter step away from zero:
`gcs.mission_files`)."""

from __future__ import annotations

import math
import struct
from typing import NamedTuple

from common.wire.mavlink import MAV
from common.wire.mission_items import GLOBAL_SCALE, HomePosition, MissionItem, xy_scale

M = MAV
KNOWN_FRAMES = frozenset(v for v in M.enums["MAV_FRAME"] if v != M.MAV_FRAME_ENUM_END)


class MissionFileError(ValueError):
    """A mission file that cannot be read: names the file, the line or item, and why."""


class MissionDoc(NamedTuple):
    """A mission file's items and the home it names (a plan's plannedHomePosition, TOML's
    [home]; None when it names none)."""

    items: list[MissionItem]
    home: HomePosition | None = None
    fmt: str = ""  # plan, wpl or toml: the format it was read in
    firmware: int | None = None  # a plan's firmwareType (MAV_AUTOPILOT); None: not said


# What MISSION_ITEM_INT can carry: a file whose values do not fit would parse and then fail
# when the upload packs the message, so such values are refused here, with the place.
_INT_RANGES = (("seq", 0, 0xFFFF), ("current", 0, 0xFF), ("frame", 0, 0xFF),
               ("command", 0, 0xFFFF), ("autocontinue", 0, 0xFF),
               ("x", -2**31, 2**31 - 1), ("y", -2**31, 2**31 - 1))
_FLOAT32 = struct.Struct("<f")


def _fits_float32(v: float) -> bool:
    try:
        _FLOAT32.pack(v)
    except OverflowError:
        return False
    return True


def checked(item: MissionItem, where: str) -> MissionItem:
    """`item` if every field fits its slot of MISSION_ITEM_INT and its frame is one of
    MAVLink's, else MissionFileError."""
    if 0 <= item.frame <= 0xFF and item.frame not in KNOWN_FRAMES:
        raise MissionFileError(f"{where}: unknown frame {item.frame} (not a MAV_FRAME)")
    for name, lo, hi in _INT_RANGES:
        v = getattr(item, name)
        if not lo <= v <= hi:
            what = "x/y out of the int32 range" if name in ("x", "y") else \
                f"{name} {v} outside {lo}..{hi}"
            raise MissionFileError(f"{where}: {what}")
    for name in ("param1", "param2", "param3", "param4", "z"):
        if not _fits_float32(getattr(item, name)):
            raise MissionFileError(f"{where}: {name} {getattr(item, name)!r} does not fit a "
                                   "float32")
    return item


def float_text(x: float) -> str:
    if math.isnan(x):
        return "nan"
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return repr(float(x))


def xy_unit(frame: int, v: int) -> float:
    """MISSION_ITEM_INT's x or y in the frame's unit, as the files write it: metres, or
    degrees a quarter step away from zero (`gcs.mission_files`)."""
    scale = xy_scale(frame)
    if scale == GLOBAL_SCALE and v:
        return (v + (0.25 if v > 0 else -0.25)) / scale
    return v / scale


def xy_int(frame: int, v: float) -> int:
    """The inverse of `_xy_unit` (rounding); OverflowError or ValueError when not finite."""
    return round(v * xy_scale(frame))

