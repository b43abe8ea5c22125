"""The readable TOML form of a mission: local NED keyframes, waypoints and the
figure-infinity by name (`[[item]]` tables), `raw` for anything else, an optional `[home]`
(ArduPilot's seq 0)."""

from __future__ import annotations

import math
import tomllib
from collections.abc import Sequence
from typing import Any

from common.config.keys import REQUIRED, Key, KeyTable
from common.wire.mav_enums import MAV_CMD as CMD
from common.wire.mavlink import MAV, MAV_CMD_FIGURE_EIGHT, MAV_CMD_POSE_KEYFRAME
from common.wire.mission_items import LOCAL_SCALE, HomePosition, MissionItem
from gcs.mission_files.items import MissionDoc, MissionFileError, checked, float_text

M = MAV
FORMAT = "dqflight-mission-1"
_KINDS = {
    M.MAV_CMD_NAV_TAKEOFF: "takeoff",
    M.MAV_CMD_NAV_WAYPOINT: "waypoint",
    M.MAV_CMD_NAV_LOITER_TIME: "loiter",
    M.MAV_CMD_NAV_LAND: "land",
    MAV_CMD_POSE_KEYFRAME: "keyframe",
    MAV_CMD_FIGURE_EIGHT: "figure_eight",
}
_NAN = math.nan
_YAW = Key("yaw_deg", "number", "heading, NED (nan: keep the attitude)", "deg", _NAN)
_POSITION = Key("position_ned_m", "vec3", "target north, east, down from home", "m")
# The keys of each kind with their MAVLink slots: p1..p4, z, xyz (a triple x, y, z), p34z (a
# triple p3, p4, z), p234 (a triple p2, p3, p4). Unlisted slots are 0. The file reader checks
# the types and fills the defaults; the vehicle checks the ranges at upload
# (docs/missions.md#upload-and-check-a-mission).
_LAYOUT: dict[str, tuple[tuple[Key, str], ...]] = {
    "takeoff": ((Key("altitude_ned_z_m", "number", "target NED z (3 m up: -3)", "m"), "z"),
                (Key("climb_time_s", "number", "climb time (0: at MIS_TKO_SPD)", "s", 0.0,
                     lo=0.0), "p2"),
                (_YAW, "p4")),
    "waypoint": ((_POSITION, "xyz"),
                 (Key("hold_s", "number", "hold after arrival", "s", lo=0.0), "p1"),
                 (_YAW, "p4")),
    "loiter": ((_POSITION, "xyz"),
               (Key("time_s", "number", "hold time (travelled to first at MIS_CRUISE_SPD)",
                    "s", lo=0.0), "p1")),
    "land": ((_YAW, "p4"),),
    "keyframe": ((_POSITION, "xyz"),
                 (Key("time_s", "number", "time to reach the pose", "s", lo=0.0,
                      lo_open=True), "p1"),
                 (Key("rotvec_ned_frd_rad", "vec3", "the NED-to-FRD attitude as a rotation "
                      "vector", "rad"), "p234")),
    "figure_eight": ((Key("amplitude_m", "number", "amplitude A of the figure-infinity", "m",
                          lo=0.0), "p1"),
                     (Key("duration_s", "number", "its duration", "s", lo=0.0, lo_open=True),
                      "p2"),
                     (Key("axis_ned", "vec3", "the rotation axis n (not normalised; not "
                          "zero)"), "p34z")),
}
_RAW = KeyTable("item[]", (
    Key("type", "string", "an item of any command, MAVLink's fields as they are", choices=(
        "raw",)),
    Key("command", "integer", "MAV_CMD"),
    Key("frame", "integer", "MAV_FRAME", default=int(M.MAV_FRAME_LOCAL_NED)),
    Key("autocontinue", "integer", "MISSION_ITEM_INT's autocontinue", default=1),
    Key("params", "numbers", "p1 to p4", n=4),
    Key("x", "integer", "MISSION_ITEM_INT's x (local: 1e-4 m; global: 1e-7 deg)"),
    Key("y", "integer", "MISSION_ITEM_INT's y"),
    Key("z", "number", "MISSION_ITEM_INT's z", "m")), title='`[[item]]` with `type = "raw"`')
_HOME = KeyTable("home", (
    Key("lat_deg", "number", "latitude", "deg", lo=-90.0, hi=90.0),
    Key("lon_deg", "number", "longitude", "deg", lo=-180.0, hi=180.0),
    Key("alt_m", "number", "altitude above mean sea level (finite)", "m")),
    note="The vehicle's home, optional (ArduPilot's mission seq 0).")
TOP_KEYS = KeyTable("", (
    Key("format", "string", "the file's format", default=FORMAT, choices=(FORMAT,)),
    Key("item", "tables", "the items, in order (one table per item, `type` naming it)",
        default=()),
    Key("home", "table", "the vehicle's home (below)", default_doc="none")))
# Every table of the file, as docs/configuration.md lists them (`python -m tools.config_doc`).
MISSION_KEYS: tuple[KeyTable, ...] = (
    TOP_KEYS, _HOME,
    *(KeyTable("item[]", (Key("type", "string", f"`{CMD(c).name}` ({c})", choices=(kind,)),
                          *(k for k, _ in _LAYOUT[kind])),
               title=f'`[[item]]` with `type = "{kind}"`') for c, kind in _KINDS.items()),
    _RAW)


def _toml_value(v: Any) -> str:
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, float):
        return float_text(v)
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
            table[key.name] = [values[f] for f in fields] if len(fields) > 1 else values[fields[0]]
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
                "[home]", f"lat_deg = {float_text(home.lat_deg)}",
                f"lon_deg = {float_text(home.lon_deg)}", f"alt_m = {float_text(home.alt_m)}", ""]
    for it in items:
        out.append("[[item]]")
        out += [f"{key} = {_toml_value(value)}" for key, value in _item_table(it).items()]
        out.append("")
    return "\n".join(out)


def _floats(t: dict[str, Any], key: str, n: int, where: str) -> list[float]:
    v = t.get(key)
    if not isinstance(v, list) or len(v) != n or not all(
            isinstance(x, int | float) and not isinstance(x, bool) for x in v):
        raise MissionFileError(f"{where}: key '{key}': expected a list of {n} numbers")
    try:
        return [float(x) for x in v]
    except OverflowError:  # an integer beyond the float range
        raise MissionFileError(f"{where}: key '{key}': number out of range") from None


def _float(t: dict[str, Any], key: str, where: str, default: float | None = None) -> float:
    v = t.get(key, default)
    if v is None or isinstance(v, bool) or not isinstance(v, int | float):
        raise MissionFileError(f"{where}: key '{key}': expected a number")
    try:
        return float(v)
    except OverflowError:
        raise MissionFileError(f"{where}: key '{key}': number out of range") from None


def _int(t: dict[str, Any], key: str, where: str, default: int | None = None) -> int:
    v = t.get(key, default)
    if v is None or isinstance(v, bool) or not isinstance(v, int):
        raise MissionFileError(f"{where}: key '{key}': expected an integer")
    return v


_RAW_KEYS = {k.name for k in _RAW.keys}
_HOME_KEYS = tuple(k.name for k in _HOME.keys)


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
        item = _raw_item(t, seq, where) if t.get("type") == "raw" else _kind_item(t, seq, where)
        items.append(checked(item, where))
    return MissionDoc(items, _toml_home(data, source), "toml")


def _raw_item(t: dict[str, Any], seq: int, where: str) -> MissionItem:
    """An [[item]] of type raw: MAVLink's fields as they are."""
    extra = set(t) - _RAW_KEYS
    if extra:
        raise MissionFileError(f"{where}: unknown key '{sorted(extra)[0]}' for raw")
    params = _floats(t, "params", 4, where)
    return MissionItem(seq, _int(t, "frame", where, M.MAV_FRAME_LOCAL_NED),
                       _int(t, "command", where), 1 if seq == 0 else 0,
                       _int(t, "autocontinue", where, 1), params[0], params[1],
                       params[2], params[3], _int(t, "x", where),
                       _int(t, "y", where), _float(t, "z", where))


def _kind_item(t: dict[str, Any], seq: int, where: str) -> MissionItem:
    """An [[item]] of a named type (waypoint, takeoff, ...): its keys in their slots, in
    MAV_FRAME_LOCAL_NED."""
    kind = t.get("type")
    command = next((c for c, k in _KINDS.items() if k == kind), None)
    if command is None:
        raise MissionFileError(f"{where}: key 'type': expected one of "
                               f"{', '.join(sorted(_KINDS.values()))}, raw; got {kind!r}")
    layout = _LAYOUT[_KINDS[command]]  # the kind's own
    extra = set(t) - {"type", *(k.name for k, _ in layout)}
    if extra:
        raise MissionFileError(f"{where}: unknown key '{sorted(extra)[0]}' for {kind}")
    p = {"p1": 0.0, "p2": 0.0, "p3": 0.0, "p4": 0.0, "x": 0.0, "y": 0.0, "z": 0.0}
    for key, slot in layout:
        fields = _FIELDS[slot]
        if len(fields) > 1:
            p.update(zip(fields, _floats(t, key.name, len(fields), where), strict=True))
        else:
            p[fields[0]] = _float(t, key.name, where,
                                  None if key.default is REQUIRED else key.default)
    try:
        x, y = round(p["x"] * LOCAL_SCALE), round(p["y"] * LOCAL_SCALE)
    except (OverflowError, ValueError):
        raise MissionFileError(f"{where}: position not finite") from None
    return MissionItem(seq, M.MAV_FRAME_LOCAL_NED, command, 1 if seq == 0 else 0, 1, p["p1"],
                       p["p2"], p["p3"], p["p4"], x, y, p["z"])
