"""Mission files: the plain-text `QGC WPL 110` (MAVProxy's `wp load` / `wp save`; QGC reads
it), QGroundControl's JSON `.plan`, and a readable TOML form for 6-DoF keyframes and the
figure-infinity.

All map onto `MissionItem` (MISSION_ITEM_INT fields). In QGC WPL and `.plan`, x and y are
written as floats in the frame's unit (metres in local frames, degrees in global ones); in
MissionItem local x, y are int32 in 1e-4 m and global ones in 1e-7 deg
(`common.mission_items.xy_scale`, the scaling of the legacy MISSION_ITEM too). Floats are
written with Python's shortest round-trip representation, so a file written from downloaded
items reads back to the same items.

Latitudes and longitudes are written a quarter of MISSION_ITEM_INT's 1e-7 deg step away from
zero from the item's integer (47.3977421 as 47.397742125): MAVProxy (`int(x * 1e7)`) and QGC
(an implicit double-to-int conversion) truncate when they upload, and a value written exactly
on the step reads back one step short about one time in sixteen (1.1 cm north); from a
quarter step, truncation and rounding both give the item's integer, and a file read here
(rounding) gives the same items. The written position is within 3 mm of the item's.

ArduPilot keeps its home at mission seq 0 (`gcs.mission_home`): a `.plan` holds it in
`plannedHomePosition`, the TOML form in an optional `[home]` table (lat_deg, lon_deg, alt_m
AMSL), and a WPL file for ArduPilot as line 0 (MAVProxy's convention). `read_mission_doc`
gives the items with the file's home; `format_mission` writes the home where the format
keeps it when the vehicle counts home in its mission (`home_at_seq0`).

MAVProxy scales x and y by 1e7 in every frame, local ones included (where MAVLink takes
1e4): a local-frame WPL file does not survive `wp load`. Write missions for MAVProxy in a
global frame (`gcs mission download --frame global`, `to_frame`).
"""

from __future__ import annotations

import json
import math
import struct
import tomllib
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NamedTuple

from common.cliargs import read_text_file
from common.mavlink import MAV, MAV_CMD_FIGURE_EIGHT, MAV_CMD_POSE_KEYFRAME
from common.mission_items import (
    GEO_FRAMES,
    GLOBAL_SCALE,
    LOCAL_SCALE,
    HomePosition,
    MissionItem,
    to_global,
    to_local,
    xy_scale,
)
from gcs.mission_home import with_home

M = MAV
WPL_HEADER = "QGC WPL 110"
FORMATS = ("plan", "wpl", "toml")
# File formats by extension; others (.txt among them) are read by their content and
# written as WPL.
EXTENSIONS = {".plan": "plan", ".waypoints": "wpl", ".toml": "toml"}
KNOWN_FRAMES = frozenset(v for v in M.enums["MAV_FRAME"] if v != M.MAV_FRAME_ENUM_END)


class MissionFileError(ValueError):
    """A mission file that cannot be read: names the file, the line or item, and why."""


class MissionDoc(NamedTuple):
    """A mission file's items and the home it names (a plan's plannedHomePosition, TOML's
    [home]; None when it names none)."""

    items: list[MissionItem]
    home: HomePosition | None = None
    fmt: str = ""  # plan, wpl or toml: the format it was read in


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


def _num(x: float) -> str:
    if math.isnan(x):
        return "nan"
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return repr(float(x))


def _xy_unit(frame: int, v: int) -> float:
    """MISSION_ITEM_INT's x or y in the frame's unit, as the files write it: metres, or
    degrees a quarter step away from zero (module docstring)."""
    scale = xy_scale(frame)
    if scale == GLOBAL_SCALE and v:
        return (v + (0.25 if v > 0 else -0.25)) / scale
    return v / scale


def _xy_int(frame: int, v: float) -> int:
    """The inverse of `_xy_unit` (rounding); OverflowError or ValueError when not finite."""
    return round(v * xy_scale(frame))


# ------------------------------------------------------------------ QGC WPL 110


def format_wpl(items: Sequence[MissionItem]) -> str:
    lines = [WPL_HEADER]
    for it in items:
        lines.append("\t".join([str(it.seq), str(it.current), str(it.frame), str(it.command),
                                *(_num(v) for v in (it.param1, it.param2, it.param3,
                                                    it.param4)),
                                _num(_xy_unit(it.frame, it.x)), _num(_xy_unit(it.frame, it.y)),
                                _num(it.z), str(it.autocontinue)]))
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
        try:
            x, y = _xy_int(frame, p[4]), _xy_int(frame, p[5])
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


def format_toml(items: Sequence[MissionItem], home: HomePosition | None = None) -> str:
    """The TOML form; `home` (ArduPilot's seq 0) as a `[home]` table when given."""
    out = ["# Mission: local NED (metres), times in seconds, yaw in degrees (nan: keep the",
           "# attitude). Item types and their MAVLink slots: docs/autopilot.md, section Missions.",
           'format = "dqflight-mission-1"', ""]
    if home is not None:
        out += ["# The vehicle's home (ArduPilot's mission seq 0): degrees, metres AMSL.",
                "[home]", f"lat_deg = {_num(home.lat_deg)}", f"lon_deg = {_num(home.lon_deg)}",
                f"alt_m = {_num(home.alt_m)}", ""]
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


_HOME_KEYS = ("lat_deg", "lon_deg", "alt_m")


def _toml_home(data: dict[str, Any], source: str) -> HomePosition | None:
    t = data.get("home")
    if t is None:
        return None
    where = f"{source}: [home]"
    if not isinstance(t, dict):
        raise MissionFileError(f"{where}: expected a table with {', '.join(_HOME_KEYS)}")
    extra = set(t) - set(_HOME_KEYS)
    if extra:
        raise MissionFileError(f"{where}: unknown key '{sorted(extra)[0]}'")
    lat, lon, alt = (_float(t, key, where) for key in _HOME_KEYS)
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0 and math.isfinite(alt)):
        raise MissionFileError(f"{where}: not a position (lat {lat}, lon {lon}, alt {alt})")
    return HomePosition(lat, lon, alt)


def parse_toml(text: str, source: str = "<mission>") -> list[MissionItem]:
    return parse_toml_doc(text, source).items


def parse_toml_doc(text: str, source: str = "<mission>") -> MissionDoc:
    """The items of the TOML form and its [home] (None without one)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise MissionFileError(f"{source}: not valid TOML: {exc}") from None
    except RecursionError:  # tomllib recurses into nested arrays and tables
        raise MissionFileError(f"{source}: not valid TOML: nested too deeply") from None
    unknown = set(data) - {"format", "item", "home"}
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
    return MissionDoc(items, _toml_home(data, source), "toml")


# ------------------------------------------------------------------ QGroundControl .plan

PLAN_FILE_TYPE = "Plan"
PLAN_VERSION = 1
PLAN_MISSION_VERSION = 2
MAV_AUTOPILOT_PX4 = 12
MAV_TYPE_HEXAROTOR = 13
MAV_CMD_DO_JUMP = 177
QGC_CRUISE_SPEED = 15.0  # QGC's default (fixed-wing cruise; a multirotor flies hoverSpeed)
# QGroundControlQmlGlobal::AltMode, as QGC writes it beside items with a coordinate
ALT_MODE_RELATIVE, ALT_MODE_ABSOLUTE = 1, 2


def _json_num(v: float) -> float | None:
    """A float for JSON: NaN as null (QGC's JsonHelper), no infinities (not JSON)."""
    if math.isnan(v):
        return None
    if math.isinf(v):
        raise MissionFileError(f"{v} cannot be written to a .plan (JSON has no infinity)")
    return v


def format_plan(items: Sequence[MissionItem], home: HomePosition | None = None, *,
                hover_speed_m_s: float = 2.0, vehicle_type: int = MAV_TYPE_HEXAROTOR,
                firmware_type: int = MAV_AUTOPILOT_PX4) -> str:
    """A QGroundControl plan (JSON, `fileType` "Plan", version 1) with `items` as SimpleItems
    (`params` p1-p4, x, y, z; doJumpId = seq + 1, DO_JUMP's p1 a doJumpId),
    `plannedHomePosition` the vehicle's home (else the first global item, else zeros),
    `firmwareType` the autopilot's MAV_AUTOPILOT (12 PX4, as this FCU; 3 ArduPilot), no
    geofence, no rally points.
    Keys sorted and 4-space indents, as QGC writes it."""
    out: list[dict[str, Any]] = []
    for it in items:
        p1 = it.param1
        if it.command == MAV_CMD_DO_JUMP and 0 <= p1 < len(items) and p1 == int(p1):
            p1 = p1 + 1.0  # a seq -> the target's doJumpId
        entry: dict[str, Any] = {
            "autoContinue": bool(it.autocontinue), "command": it.command, "doJumpId": it.seq + 1,
            "frame": it.frame, "type": "SimpleItem",
            "params": [_json_num(v) for v in (p1, it.param2, it.param3, it.param4,
                                              _xy_unit(it.frame, it.x),
                                              _xy_unit(it.frame, it.y), it.z)]}
        if it.frame in GEO_FRAMES:
            entry["AMSLAltAboveTerrain"] = None
            entry["Altitude"] = _json_num(it.z)
            entry["AltitudeMode"] = ALT_MODE_ABSOLUTE if it.frame in (
                M.MAV_FRAME_GLOBAL, M.MAV_FRAME_GLOBAL_INT) else ALT_MODE_RELATIVE
        out.append(entry)
    if home is not None:
        planned = [home.lat_deg, home.lon_deg, home.alt_m]
    else:
        first = next((it for it in items if it.frame in GEO_FRAMES), None)
        planned = [0.0, 0.0, 0.0] if first is None else \
            [first.x / GLOBAL_SCALE, first.y / GLOBAL_SCALE, 0.0]
    doc = {
        "fileType": PLAN_FILE_TYPE,
        "geoFence": {"circles": [], "polygons": [], "version": 2},
        "groundStation": "dqflight",
        "mission": {"cruiseSpeed": QGC_CRUISE_SPEED, "firmwareType": firmware_type,
                    "globalPlanAltitudeMode": ALT_MODE_RELATIVE,
                    "hoverSpeed": hover_speed_m_s, "items": out,
                    "plannedHomePosition": planned, "vehicleType": vehicle_type,
                    "version": PLAN_MISSION_VERSION},
        "rallyPoints": {"points": [], "version": 2},
        "version": PLAN_VERSION,
    }
    return json.dumps(doc, indent=4, sort_keys=True, allow_nan=False) + "\n"


def _no_constant(name: str) -> float:
    raise MissionFileError(f"{name} is not JSON (QGC writes NaN as null)")


def _plan_key(obj: dict[str, Any], key: str, kind: type, where: str, what: str) -> Any:
    """obj[key] of type `kind` (int: an integral JSON number, as QGC reads it)."""
    v = obj.get(key)
    if kind is int and isinstance(v, float) and v.is_integer():
        v = int(v)
    if v is None or not isinstance(v, kind) or (isinstance(v, bool) and kind is not bool):
        raise MissionFileError(f"{where}: key '{key}': expected {what}")
    return v


def _plan_param(v: Any, where: str, n: int) -> float:
    if v is None:
        return math.nan  # QGC's null
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise MissionFileError(f"{where}: params[{n}]: expected a number or null")
    try:
        return float(v)
    except OverflowError:
        raise MissionFileError(f"{where}: params[{n}]: number out of range") from None


def parse_plan(text: str, source: str = "<mission>") -> list[MissionItem]:
    """The mission of a QGroundControl plan (version 1, mission version 2; SimpleItems only:
    QGC's complex items, such as surveys, are refused). null parameters are NaN; geofence
    and rally points are ignored."""
    return parse_plan_doc(text, source).items


def parse_plan_doc(text: str, source: str = "<mission>") -> MissionDoc:
    """`parse_plan`'s items and the plan's `plannedHomePosition` [lat, lon, alt AMSL] (None
    when absent or [0, 0, 0], which QGC and `format_plan` write when no home is known)."""
    try:
        doc = json.loads(text, parse_constant=_no_constant)
    except MissionFileError as exc:
        raise MissionFileError(f"{source}: {exc}") from None
    except (json.JSONDecodeError, RecursionError) as exc:
        raise MissionFileError(f"{source}: not valid JSON: {exc}") from None
    if not isinstance(doc, dict):
        raise MissionFileError(f"{source}: expected a JSON object (a QGC plan)")
    if doc.get("fileType") != PLAN_FILE_TYPE:
        raise MissionFileError(f"{source}: key 'fileType': expected \"{PLAN_FILE_TYPE}\", got "
                               f"{doc.get('fileType')!r}")
    if doc.get("version") != PLAN_VERSION:
        raise MissionFileError(f"{source}: key 'version': only plan version {PLAN_VERSION} is "
                               f"supported, got {doc.get('version')!r}")
    mission = _plan_key(doc, "mission", dict, source, "an object")
    where = f"{source}: mission"
    if mission.get("version") != PLAN_MISSION_VERSION:
        raise MissionFileError(f"{where}: key 'version': only mission version "
                               f"{PLAN_MISSION_VERSION} is supported")
    entries = _plan_key(mission, "items", list, where, "a list")
    home = mission.get("plannedHomePosition")
    if home is not None and not (isinstance(home, list) and len(home) == 3 and all(
            isinstance(v, int | float) and not isinstance(v, bool) for v in home)):
        raise MissionFileError(f"{where}: key 'plannedHomePosition': expected [lat, lon, alt]")
    items: list[MissionItem] = []
    jump_ids: dict[int, int] = {}
    for seq, entry in enumerate(entries):
        where = f"{source}: item {seq + 1}"
        if not isinstance(entry, dict):
            raise MissionFileError(f"{where}: expected an object")
        kind = entry.get("type")
        if kind != "SimpleItem":
            what = f" ({entry.get('complexItemType')})" if kind == "ComplexItem" else ""
            raise MissionFileError(f"{where}: key 'type': only SimpleItem is supported, got "
                                   f"{kind!r}{what}")
        command = _plan_key(entry, "command", int, where, "an integer")
        frame = _plan_key(entry, "frame", int, where, "an integer")
        auto = _plan_key(entry, "autoContinue", bool, where, "true or false")
        params = _plan_key(entry, "params", list, where, "a list of 7 numbers or null")
        if len(params) != 7:
            raise MissionFileError(f"{where}: key 'params': expected 7 values, got "
                                   f"{len(params)}")
        p = [_plan_param(v, where, n) for n, v in enumerate(params)]
        jump_id = entry.get("doJumpId", seq + 1)
        if isinstance(jump_id, int) and not isinstance(jump_id, bool):
            jump_ids.setdefault(jump_id, seq)
        try:
            x, y = _xy_int(frame, p[4]), _xy_int(frame, p[5])
        except (OverflowError, ValueError):
            raise MissionFileError(f"{where}: x/y (params[4], params[5]) not finite") from None
        mode, alt = entry.get("AltitudeMode"), entry.get("Altitude")
        if mode in (ALT_MODE_RELATIVE, ALT_MODE_ABSOLUTE) and isinstance(alt, int | float) \
                and not isinstance(alt, bool) and float(alt) != p[6]:
            raise MissionFileError(f"{where}: 'Altitude' {alt} differs from params[6] {p[6]}")
        items.append(_checked(MissionItem(seq, frame, command, int(seq == 0), int(auto), p[0],
                                          p[1], p[2], p[3], x, y, p[6]), where))
    for i, it in enumerate(items):  # DO_JUMP: QGC's p1 is the target's doJumpId
        if it.command == MAV_CMD_DO_JUMP and math.isfinite(it.param1):
            target = jump_ids.get(int(it.param1)) if it.param1.is_integer() else None
            if target is None:
                raise MissionFileError(f"{source}: item {i + 1}: DO_JUMP to doJumpId "
                                       f"{it.param1:g}, which no item has")
            items[i] = it._replace(param1=float(target))
    planned = None if home is None or all(v == 0 for v in home) else \
        HomePosition(float(home[0]), float(home[1]), float(home[2]))
    return MissionDoc(items, planned, "plan")


# ------------------------------------------------------------------ frames


def to_frame(items: Sequence[MissionItem], frame: str | None,
             home: HomePosition | None) -> list[MissionItem]:
    """The items with their positions in "global" (MAV_FRAME_GLOBAL_RELATIVE_ALT: lat, lon
    in degrees, altitude above home) or "local" (MAV_FRAME_LOCAL_NED) frames, through the
    vehicle's home (`common.mission_items.to_global` / `to_local`); None: as they are.
    Items whose command has no position semantics here keep their frame."""
    if frame is None:
        return list(items)
    if home is None:
        raise MissionFileError(f"--frame {frame} needs the vehicle's home position")
    if frame == "global":
        return [to_global(it, home) for it in items]
    if frame == "local":
        return [to_local(it, home) for it in items]
    raise ValueError(f"unknown frame choice {frame!r}")


# ------------------------------------------------------------------ files


def file_format(path: Path | None, fmt: str | None = None, text: str | None = None) -> str:
    """The format of a mission file: `fmt` if given, else by extension (`EXTENSIONS`), else
    by content when `text` is given (a JSON object: plan; `QGC WPL`: wpl; else toml), else
    wpl (`.txt`, as MAVProxy names them)."""
    if fmt is not None:
        if fmt not in FORMATS:
            raise MissionFileError(f"unknown mission file format {fmt!r} (plan, wpl, toml)")
        return fmt
    by_ext = EXTENSIONS.get(path.suffix.lower()) if path is not None else None
    if by_ext is not None:
        return by_ext
    if text is not None:
        head = text.lstrip()
        if head.startswith("{"):
            return "plan"
        return "wpl" if head.startswith("QGC WPL") else "toml"
    return "wpl"


def parse_mission(text: str, fmt: str, source: str = "<mission>") -> list[MissionItem]:
    """Items of a mission text in `fmt` (plan, wpl or toml)."""
    return parse_mission_doc(text, fmt, source).items


def parse_mission_doc(text: str, fmt: str, source: str = "<mission>") -> MissionDoc:
    """Items and home of a mission text in `fmt` (plan, wpl or toml; WPL names no home
    apart from its lines: `gcs.mission_home.for_ardupilot` reads line 0)."""
    if fmt == "plan":
        return parse_plan_doc(text, source)
    if fmt == "wpl":
        return MissionDoc(parse_wpl(text, source), fmt="wpl")
    return parse_toml_doc(text, source)


def format_mission(items: Sequence[MissionItem], fmt: str,
                   home: HomePosition | None = None, *, home_at_seq0: bool = False,
                   firmware_type: int = MAV_AUTOPILOT_PX4,
                   vehicle_type: int = MAV_TYPE_HEXAROTOR) -> str:
    """A mission text in `fmt` (plan, wpl or toml); `home` is the plan's planned home. With
    `home_at_seq0` (ArduPilot) `home` is also written where the format keeps it: WPL's line
    0 (the items from line 1), TOML's [home]."""
    if fmt == "plan":
        return format_plan(items, home, firmware_type=firmware_type,
                           vehicle_type=vehicle_type)
    keep = home if home_at_seq0 else None
    if fmt == "wpl":
        return format_wpl(items if keep is None else with_home(items, keep))
    return format_toml(items, keep)


def read_mission(path: Path, fmt: str | None = None) -> list[MissionItem]:
    """A mission file: `fmt` (plan, wpl, toml), else by extension (.plan, .waypoints,
    .toml), else by content (a JSON object, a `QGC WPL` header, or TOML)."""
    return read_mission_doc(path, fmt).items


def read_mission_doc(path: Path, fmt: str | None = None) -> MissionDoc:
    """`read_mission`'s items with the home the file names (`MissionDoc`)."""
    text = read_text_file(path, MissionFileError)
    doc = parse_mission_doc(text, file_format(path, fmt, text), str(path))
    if not doc.items:
        raise MissionFileError(f"{path}: no mission items (use `gcs mission clear` to clear)")
    return doc


def write_mission(path: Path, items: Sequence[MissionItem], fmt: str | None = None,
                  home: HomePosition | None = None) -> None:
    """`fmt` plan, wpl or toml; by default by extension (.plan, .toml, others QGC WPL)."""
    path.write_text(format_mission(items, file_format(path, fmt), home))
