"""QGroundControl's JSON `.plan`: the mission as SimpleItems (QGC's complex items are
refused), its planned home, DO_JUMP targets as doJumpIds; geofence and rally points empty."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from typing import Any

from common.wire.mavlink import MAV
from common.wire.mission_items import GEO_FRAMES, GLOBAL_SCALE, HomePosition, MissionItem
from gcs.mission_files.items import MissionDoc, MissionFileError, checked, xy_int, xy_unit

M = MAV
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
                                              xy_unit(it.frame, it.x),
                                              xy_unit(it.frame, it.y), it.z)]}
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
    doc = _plan_json(text, source)
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
    jump_ids: dict[int, int] = {}
    items = [_plan_item(entry, seq, f"{source}: item {seq + 1}", jump_ids)
             for seq, entry in enumerate(entries)]
    _resolve_jumps(items, jump_ids, source)
    planned = None if home is None or all(v == 0 for v in home) else \
        HomePosition(float(home[0]), float(home[1]), float(home[2]))
    firmware = mission.get("firmwareType")
    if firmware is not None and (isinstance(firmware, bool) or not isinstance(firmware, int)):
        raise MissionFileError(f"{source}: mission: key 'firmwareType': expected an integer "
                               "(MAV_AUTOPILOT)")
    return MissionDoc(items, planned, "plan", firmware)


def _plan_json(text: str, source: str) -> dict[str, Any]:
    """The plan's JSON object, its file type and plan version checked."""
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
    return doc


def _plan_item(entry: Any, seq: int, where: str, jump_ids: dict[int, int]) -> MissionItem:
    """One SimpleItem of the plan as item `seq`, checked; its doJumpId noted in
    `jump_ids` (the first item that has it)."""
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
        x, y = xy_int(frame, p[4]), xy_int(frame, p[5])
    except (OverflowError, ValueError):
        raise MissionFileError(f"{where}: x/y (params[4], params[5]) not finite") from None
    mode, alt = entry.get("AltitudeMode"), entry.get("Altitude")
    if mode in (ALT_MODE_RELATIVE, ALT_MODE_ABSOLUTE) and isinstance(alt, int | float) \
            and not isinstance(alt, bool) and float(alt) != p[6]:
        raise MissionFileError(f"{where}: 'Altitude' {alt} differs from params[6] {p[6]}")
    return checked(MissionItem(seq, frame, command, int(seq == 0), int(auto), p[0], p[1], p[2],
                               p[3], x, y, p[6]), where)


def _resolve_jumps(items: list[MissionItem], jump_ids: dict[int, int], source: str) -> None:
    """DO_JUMP: QGC's p1 is the target's doJumpId, made its sequence number in place."""
    for i, it in enumerate(items):
        if it.command == MAV_CMD_DO_JUMP and math.isfinite(it.param1):
            target = jump_ids.get(int(it.param1)) if it.param1.is_integer() else None
            if target is None:
                raise MissionFileError(f"{source}: item {i + 1}: DO_JUMP to doJumpId "
                                       f"{it.param1:g}, which no item has")
            items[i] = it._replace(param1=float(target))
