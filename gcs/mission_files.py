"""Mission files: the QGroundControl plain-text format (`QGC WPL 110`, which MAVProxy and QGC
read and write) and a readable TOML form for 6-DoF keyframes and the figure-infinity.

Both map onto `MissionItem` (MISSION_ITEM_INT fields). In QGC WPL, x and y are written as
floats in the frame's unit (metres in local frames, degrees in global ones); in MissionItem
local x, y are int32 in 1e-4 m and global ones in 1e-7 deg (`common.mission_items.xy_scale`,
the scaling of the legacy MISSION_ITEM too). Floats are written with Python's
shortest round-trip representation, so a file written from downloaded items reads back to
the same items.
"""

from __future__ import annotations

import math
import struct
import tomllib
from pathlib import Path
from typing import Any

from common.mavlink import MAV, MAV_CMD_FIGURE_EIGHT, MAV_CMD_POSE_KEYFRAME
from common.mission_items import LOCAL_SCALE, MissionItem, xy_scale

M = MAV
WPL_HEADER = "QGC WPL 110"


class MissionFileError(ValueError):
    """A mission file that cannot be read: names the file, the line or item, and why."""


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


def _checked(item: MissionItem, where: str) -> MissionItem:
    """`item` if every field fits its slot of MISSION_ITEM_INT, else MissionFileError."""
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


def _num(x: float) -> str:
    if math.isnan(x):
        return "nan"
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return repr(float(x))


# ------------------------------------------------------------------ QGC WPL 110


def format_wpl(items: list[MissionItem]) -> str:
    lines = [WPL_HEADER]
    for it in items:
        s = xy_scale(it.frame)
        lines.append("\t".join([str(it.seq), str(it.current), str(it.frame), str(it.command),
                                *(_num(v) for v in (it.param1, it.param2, it.param3,
                                                    it.param4)),
                                _num(it.x / s), _num(it.y / s), _num(it.z),
                                str(it.autocontinue)]))
    return "\n".join(lines) + "\n"


def parse_wpl(text: str, source: str = "<mission>") -> list[MissionItem]:
    lines = text.splitlines()
    if not lines or not lines[0].strip().startswith("QGC WPL"):
        raise MissionFileError(f"{source}: line 1: expected the header '{WPL_HEADER}'")
    if lines[0].split()[-1] != "110":
        raise MissionFileError(f"{source}: line 1: only version 110 is supported")
    items = []
    for n, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        fields = line.split("\t") if "\t" in line else line.split()
        if len(fields) != 12:
            raise MissionFileError(f"{source}: line {n}: expected 12 fields, got {len(fields)}")
        try:
            seq, current, frame, command = (int(f) for f in fields[:4])
            p = [float(f) for f in fields[4:11]]
            autocontinue = int(fields[11])
        except ValueError as exc:
            raise MissionFileError(f"{source}: line {n}: {exc}") from None
        s = xy_scale(frame)
        try:
            x, y = round(p[4] * s), round(p[5] * s)
        except (OverflowError, ValueError):
            raise MissionFileError(f"{source}: line {n}: x/y not finite") from None
        items.append(_checked(MissionItem(seq, frame, command, current, autocontinue, p[0],
                                          p[1], p[2], p[3], x, y, p[6]),
                              f"{source}: line {n}"))
    return items


# ------------------------------------------------------------------ TOML

_KINDS = {
    M.MAV_CMD_NAV_TAKEOFF: "takeoff",
    M.MAV_CMD_NAV_WAYPOINT: "waypoint",
    M.MAV_CMD_NAV_LOITER_TIME: "loiter",
    M.MAV_CMD_NAV_LAND: "land",
    MAV_CMD_POSE_KEYFRAME: "keyframe",
    MAV_CMD_FIGURE_EIGHT: "figure_eight",
}
# TOML keys per kind: (key, slot) with slot one of p1..p4, xyz (a triple x, y, z), p34z
# (a triple p3, p4, z), p234 (a triple p2, p3, p4). Unlisted slots must be 0 (or NaN for p4).
_LAYOUT: dict[str, tuple[tuple[str, str], ...]] = {
    "takeoff": (("altitude_ned_z_m", "z"), ("climb_time_s", "p2"), ("yaw_deg", "p4")),
    "waypoint": (("position_ned_m", "xyz"), ("hold_s", "p1"), ("yaw_deg", "p4")),
    "loiter": (("position_ned_m", "xyz"), ("time_s", "p1")),
    "land": (("yaw_deg", "p4"),),
    "keyframe": (("position_ned_m", "xyz"), ("time_s", "p1"), ("rotvec_ned_frd_rad", "p234")),
    "figure_eight": (("amplitude_m", "p1"), ("duration_s", "p2"), ("axis_ned", "p34z")),
}


def _toml_value(v: Any) -> str:
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, float):
        return _num(v)
    if isinstance(v, str):
        return '"' + v + '"'
    return str(v)


_FIELDS = {"p1": ("p1",), "p2": ("p2",), "p3": ("p3",), "p4": ("p4",), "z": ("z",),
           "xyz": ("x", "y", "z"), "p34z": ("p3", "p4", "z"), "p234": ("p2", "p3", "p4")}


def _values(it: MissionItem) -> dict[str, float]:
    return {"p1": it.param1, "p2": it.param2, "p3": it.param3, "p4": it.param4,
            "x": it.x / LOCAL_SCALE, "y": it.y / LOCAL_SCALE, "z": it.z}


def _item_table(it: MissionItem) -> dict[str, Any]:
    """The readable form when the item fits its kind's layout exactly, else `raw`."""
    kind = _KINDS.get(it.command)
    if kind is not None and it.frame == M.MAV_FRAME_LOCAL_NED and it.autocontinue == 1:
        values = _values(it)
        table: dict[str, Any] = {"type": kind}
        used: set[str] = set()
        for key, slot in _LAYOUT[kind]:
            fields = _FIELDS[slot]
            used.update(fields)
            table[key] = [values[f] for f in fields] if len(fields) > 1 else values[fields[0]]
        if all(v == 0.0 for f, v in values.items() if f not in used):
            return table
    return {"type": "raw", "command": it.command, "frame": it.frame,
            "autocontinue": it.autocontinue,
            "params": [it.param1, it.param2, it.param3, it.param4], "x": it.x, "y": it.y,
            "z": it.z}


def format_toml(items: list[MissionItem]) -> str:
    out = ["# Mission: local NED (metres), times in seconds, yaw in degrees (nan: keep the",
           "# attitude). Item types and their MAVLink slots: README, section Missions.",
           'format = "dqflight-mission-1"', ""]
    for it in items:
        out.append("[[item]]")
        out += [f"{key} = {_toml_value(value)}" for key, value in _item_table(it).items()]
        out.append("")
    return "\n".join(out)


def _floats(t: dict, key: str, n: int, where: str) -> list[float]:
    v = t.get(key)
    if not isinstance(v, list) or len(v) != n or not all(
            isinstance(x, int | float) and not isinstance(x, bool) for x in v):
        raise MissionFileError(f"{where}: key '{key}': expected a list of {n} numbers")
    try:
        return [float(x) for x in v]
    except OverflowError:  # an integer beyond the float range
        raise MissionFileError(f"{where}: key '{key}': number out of range") from None


def _float(t: dict, key: str, where: str, default: float | None = None) -> float:
    v = t.get(key, default)
    if v is None or isinstance(v, bool) or not isinstance(v, int | float):
        raise MissionFileError(f"{where}: key '{key}': expected a number")
    try:
        return float(v)
    except OverflowError:
        raise MissionFileError(f"{where}: key '{key}': number out of range") from None


def _int(t: dict, key: str, where: str, default: int | None = None) -> int:
    v = t.get(key, default)
    if v is None or isinstance(v, bool) or not isinstance(v, int):
        raise MissionFileError(f"{where}: key '{key}': expected an integer")
    return v


_RAW_KEYS = {"type", "command", "frame", "autocontinue", "params", "x", "y", "z"}
FORMAT = "dqflight-mission-1"


def parse_toml(text: str, source: str = "<mission>") -> list[MissionItem]:
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise MissionFileError(f"{source}: not valid TOML: {exc}") from None
    except RecursionError:  # tomllib recurses into nested arrays and tables
        raise MissionFileError(f"{source}: not valid TOML: nested too deeply") from None
    unknown = set(data) - {"format", "item"}
    if unknown:
        raise MissionFileError(f"{source}: unknown key '{sorted(unknown)[0]}'")
    if data.get("format", FORMAT) != FORMAT:
        raise MissionFileError(f"{source}: key 'format': expected \"{FORMAT}\"")
    tables = data.get("item", [])
    if not isinstance(tables, list) or not all(isinstance(t, dict) for t in tables):
        raise MissionFileError(f"{source}: key 'item': expected tables [[item]]")
    items = []
    for seq, t in enumerate(tables):
        where = f"{source}: item {seq + 1}"
        kind = t.get("type")
        if kind == "raw":
            extra = set(t) - _RAW_KEYS
            if extra:
                raise MissionFileError(f"{where}: unknown key '{sorted(extra)[0]}' for raw")
            params = _floats(t, "params", 4, where)
            item = MissionItem(seq, _int(t, "frame", where, M.MAV_FRAME_LOCAL_NED),
                               _int(t, "command", where), 1 if seq == 0 else 0,
                               _int(t, "autocontinue", where, 1), params[0], params[1],
                               params[2], params[3], _int(t, "x", where),
                               _int(t, "y", where), _float(t, "z", where))
            items.append(_checked(item, where))
            continue
        command = next((c for c, k in _KINDS.items() if k == kind), None)
        if command is None:
            raise MissionFileError(f"{where}: key 'type': expected one of "
                                   f"{', '.join(sorted(_KINDS.values()))}, raw; got {kind!r}")
        layout = dict(_LAYOUT[kind])
        extra = set(t) - {"type", *layout}
        if extra:
            raise MissionFileError(f"{where}: unknown key '{sorted(extra)[0]}' for {kind}")
        p = {"p1": 0.0, "p2": 0.0, "p3": 0.0, "p4": 0.0, "x": 0.0, "y": 0.0, "z": 0.0}
        for key, slot in layout.items():
            fields = _FIELDS[slot]
            if len(fields) > 1:
                p.update(zip(fields, _floats(t, key, len(fields), where), strict=True))
            elif key == "yaw_deg" or (kind == "takeoff" and key == "climb_time_s"):
                p[fields[0]] = _float(t, key, where, math.nan if key == "yaw_deg" else 0.0)
            else:
                p[fields[0]] = _float(t, key, where)
        try:
            x, y = round(p["x"] * LOCAL_SCALE), round(p["y"] * LOCAL_SCALE)
        except (OverflowError, ValueError):
            raise MissionFileError(f"{where}: position not finite") from None
        items.append(_checked(MissionItem(seq, M.MAV_FRAME_LOCAL_NED, command,
                                          1 if seq == 0 else 0, 1, p["p1"], p["p2"], p["p3"],
                                          p["p4"], x, y, p["z"]), where))
    return items


# ------------------------------------------------------------------ files


def read_mission(path: Path) -> list[MissionItem]:
    """A mission file, by content: `QGC WPL` header or TOML."""
    try:
        text = path.read_text()
    except OSError as exc:
        raise MissionFileError(f"{path}: {exc.strerror}") from None
    except UnicodeDecodeError as exc:
        raise MissionFileError(f"{path}: not a text file ({exc.reason} at byte "
                               f"{exc.start})") from None
    items = parse_wpl(text, str(path)) if text.lstrip().startswith("QGC WPL") \
        else parse_toml(text, str(path))
    if not items:
        raise MissionFileError(f"{path}: no mission items (use `gcs mission clear` to clear)")
    return items


def write_mission(path: Path, items: list[MissionItem], fmt: str | None = None) -> None:
    """`fmt` "toml" or "wpl"; by default `.toml` files get the TOML form, others QGC WPL."""
    toml = fmt == "toml" or (fmt is None and path.suffix == ".toml")
    path.write_text(format_toml(items) if toml else format_wpl(items))
