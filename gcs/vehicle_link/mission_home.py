"""ArduPilot's mission numbering: seq 0 is the vehicle's home, always, and the first item of
a plan is seq 1 (MAVLink's mission protocol, "ArduPilot"). PX4 (and this project's FCU)
number a plan's items from 0 and keep home out of the mission.

Files keep home apart from the items: a QGC `.plan` in `plannedHomePosition`, the TOML
form in its `[home]` table; a `QGC WPL 110` file written for ArduPilot (MAVProxy's and
Mission Planner's) has home as line 0. `with_home` puts the home before a plan's items for
the wire and `split_home` takes it off again; DO_JUMP targets (a seq) move with them.

The home item is what QGC sends and ArduPilot answers: MAV_CMD_NAV_WAYPOINT in
MAV_FRAME_GLOBAL (altitude AMSL), lat, lon in 1e-7 deg. ArduPilot answers seq 0 with its
own home whatever was uploaded there (the upload does not move its home).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

from common.wire.mission_items import (
    AMSL_FRAMES,
    GLOBAL_FRAMES,
    GLOBAL_SCALE,
    MAV_FRAME_GLOBAL,
    MAV_FRAME_LOCAL_NED,
    XY_COMMANDS,
    HomePosition,
    MissionItem,
    to_global,
)

MAV_CMD_NAV_WAYPOINT = 16
MAV_CMD_DO_JUMP = 177


class HomeError(ValueError):
    """A mission for ArduPilot whose home cannot be known (no planned home, none heard)."""


def home_item(home: HomePosition) -> MissionItem:
    """Seq 0 for ArduPilot: a NAV_WAYPOINT at `home` (MAV_FRAME_GLOBAL, altitude AMSL)."""
    return MissionItem(0, MAV_FRAME_GLOBAL, MAV_CMD_NAV_WAYPOINT, 0, 1, 0.0, 0.0, 0.0, 0.0,
                       round(home.lat_deg * GLOBAL_SCALE), round(home.lon_deg * GLOBAL_SCALE),
                       home.alt_m)


def is_home_item(item: MissionItem) -> bool:
    """Whether `item` can be ArduPilot's home line: seq 0, a NAV_WAYPOINT at an AMSL
    position (as ArduPilot, MAVProxy and QGC write it)."""
    return item.seq == 0 and item.command == MAV_CMD_NAV_WAYPOINT and \
        item.frame in AMSL_FRAMES and math.isfinite(item.z)


def home_of(item: MissionItem) -> HomePosition:
    """The home that a home item (`is_home_item`) holds."""
    return HomePosition(item.x / GLOBAL_SCALE, item.y / GLOBAL_SCALE, float(item.z))


def _jumps_moved(items: Sequence[MissionItem], by: int) -> list[MissionItem]:
    """The items with each DO_JUMP's target seq (param1) moved by `by`; a target that would
    leave the mission (a jump to ArduPilot's home) stays as it is."""
    out = []
    for it in items:
        p1 = it.param1
        if it.command == MAV_CMD_DO_JUMP and math.isfinite(p1) and p1.is_integer() and \
                p1 + by >= 0:
            it = it._replace(param1=p1 + by)
        out.append(it)
    return out


def with_home(items: Sequence[MissionItem], home: HomePosition) -> list[MissionItem]:
    """ArduPilot's wire mission: the home item at seq 0, then every item from seq 1 (the
    first item keeps `current`; DO_JUMP targets move up by one)."""
    moved = _jumps_moved(items, 1)
    return [home_item(home), *(it._replace(seq=i + 1) for i, it in enumerate(moved))]


def split_home(wire: Sequence[MissionItem]) -> tuple[HomePosition | None, list[MissionItem]]:
    """(home, items numbered from 0) of ArduPilot's wire mission; (None, []) for an empty
    one. Seq 0 is home whatever it holds (ArduPilot's rule); DO_JUMP targets move down."""
    if not wire:
        return None, []
    first = wire[0]
    home = home_of(first) if first.frame in GLOBAL_FRAMES else None
    rest = [it._replace(seq=i) for i, it in enumerate(wire[1:])]
    return home, _jumps_moved(rest, -1)


class WireMission(NamedTuple):
    """A mission as it goes on the wire, with the home sent at seq 0 and where it came from
    (None for PX4: no home item)."""

    items: list[MissionItem]
    home: HomePosition | None = None
    home_source: str = ""


def _local_for_ardupilot(item: MissionItem, home: HomePosition) -> MissionItem:
    """A local item in MAV_FRAME_GLOBAL_RELATIVE_ALT through `home`; where its command does
    not use x, y (NAV_TAKEOFF, NAV_LAND: climb or land where the vehicle is), lat = lon = 0,
    ArduPilot's "where the vehicle is": a NAV_LAND at home's latitude and longitude would
    fly there first (ArduCopter's ModeAuto::do_land)."""
    converted = to_global(item, home)
    if converted is item or item.command in XY_COMMANDS:
        return converted
    return converted._replace(x=0, y=0)


def for_ardupilot(items: Sequence[MissionItem], fmt: str, file_home: HomePosition | None,
                  vehicle_home: HomePosition | None) -> WireMission:
    """The wire mission for ArduPilot of a file's items (`fmt` plan, wpl, toml) and its
    home (a plan's plannedHomePosition, TOML's [home]), else the vehicle's home.

    A WPL file whose line 0 is a home item (`is_home_item`) goes as it is (MAVProxy's
    convention); any other file gets a home item at seq 0 and its items from seq 1, so that
    none is lost. Items in MAV_FRAME_LOCAL_NED, which ArduPilot refuses, are sent in
    MAV_FRAME_GLOBAL_RELATIVE_ALT through the vehicle's home (`_local_for_ardupilot`).
    HomeError when a home is needed and none is known."""
    if any(it.frame == MAV_FRAME_LOCAL_NED for it in items):
        if vehicle_home is None:
            raise HomeError("local-frame items need the vehicle's home position to go to "
                            "ArduPilot (in a global frame), and it sent no HOME_POSITION")
        items = [_local_for_ardupilot(it, vehicle_home) for it in items]
    if fmt == "wpl" and items and is_home_item(items[0]):
        return WireMission([it._replace(seq=i) for i, it in enumerate(items)],
                           home_of(items[0]), "the file's line 0")
    if file_home is not None:
        source = "the plan's plannedHomePosition" if fmt == "plan" else "the file's [home]"
        return WireMission(with_home(items, file_home), file_home, source)
    if vehicle_home is None:
        raise HomeError("ArduPilot keeps home at mission seq 0: the file has no home "
                        "(plannedHomePosition, [home]) and the vehicle sent no "
                        "HOME_POSITION")
    return WireMission(with_home(items, vehicle_home), vehicle_home,
                       "the vehicle's HOME_POSITION")


def yaw_ignored(items: Sequence[MissionItem]) -> list[int]:
    """The seq of each NAV_WAYPOINT with a yaw (param4 finite, not 0) among the items of a
    plan (seq 0 its first item): ArduCopter keeps only a waypoint's param1, the delay
    (AP_Mission's mavlink_int_to_mission_cmd), so it flies none of these yaws."""
    return [i for i, it in enumerate(items) if it.command == MAV_CMD_NAV_WAYPOINT and
            math.isfinite(it.param4) and it.param4 != 0.0]


# ------------------------------------------------------------------ another firmware's plan

FIRMWARE_NAMES = {0: "a generic autopilot", 3: "ArduPilot", 12: "PX4"}


def firmware_name(firmware: int) -> str:
    """'PX4', 'ArduPilot', ... as a plan's firmwareType (MAV_AUTOPILOT) names it."""
    return FIRMWARE_NAMES.get(firmware, f"MAV_AUTOPILOT {firmware}")


class Conversion(NamedTuple):
    """What uploading another firmware's plan converts (`notice`), and why it cannot go
    (`refusal`, empty when the conversion is exact)."""

    notice: str
    refusal: str = ""


def plan_conversion(plan_firmware: int | None, vehicle_firmware: int,
                    items: Sequence[MissionItem]) -> Conversion | None:
    """The conversion a plan written for `plan_firmware` needs on a `vehicle_firmware`
    vehicle (None when it was written for this firmware, or says none or generic).

    For ArduPilot from another firmware: the home goes at seq 0, the items from seq 1 and
    DO_JUMP targets one up (exact); local-frame items would go through the vehicle's home
    in a global frame, rounded to 1e-7 deg: not exact, refused. For PX4 (and this FCU) from
    ArduPilot: the planned home stays on the ground station (PX4 keeps home out of the
    mission), the items go from seq 0 as they are (exact)."""
    if plan_firmware in (None, 0, vehicle_firmware):
        return None
    head = (f"plan written for {firmware_name(plan_firmware)} (firmwareType "
            f"{plan_firmware}), the vehicle is {firmware_name(vehicle_firmware)} "
            f"({vehicle_firmware})")
    if vehicle_firmware == 3:
        local = [i + 1 for i, it in enumerate(items) if it.frame == MAV_FRAME_LOCAL_NED]
        if local:
            return Conversion(head, f"{head}: its local-frame item(s) {_ranges(local)} would "
                              "go in a global frame through the vehicle's home, rounded to "
                              "1e-7 deg: not an exact conversion; nothing sent")
        jumps = any(it.command == MAV_CMD_DO_JUMP for it in items)
        return Conversion(f"{head}: converted: home at seq 0, the plan's items from seq 1"
                          + (", DO_JUMP targets one up" if jumps else ""))
    return Conversion(f"{head}: converted: the planned home is not sent (the vehicle keeps "
                      "home out of the mission), the items go from seq 0 as they are")


# ------------------------------------------------------------------ after a refused upload


def _ranges(seqs: Sequence[int]) -> str:
    """'0-2, 5' of ascending numbers."""
    runs: list[list[int]] = []
    for s in seqs:
        if runs and runs[-1][1] == s - 1:
            runs[-1][1] = s
        else:
            runs.append([s, s])
    return ", ".join(f"{a}" if a == b else f"{a}-{b}" for a, b in runs)


def same_item(a: MissionItem, b: MissionItem) -> bool:
    """Whether two items are the same mission item (seq and current apart; NaN equals
    NaN)."""
    def fields(it: MissionItem) -> tuple[object, ...]:
        return tuple("nan" if isinstance(v, float) and math.isnan(v) else v
                     for v in (it.frame, it.command, it.autocontinue, it.param1, it.param2,
                               it.param3, it.param4, it.x, it.y, it.z))
    return fields(a) == fields(b)


def after_refusal(held: Sequence[str], count: int, received: int, label: str) -> list[str]:
    """Which mission an ArduPilot vehicle holds at each seq (labels, e.g. "new", "old")
    after it refused an upload of `count` items labelled `label` once it had taken
    `received` of them, over a mission labelled `held`: ArduPilot's GCS_MAVLink mission
    protocol truncates its mission to the new count when the upload starts (MISSION_COUNT)
    and writes each item as it comes."""
    kept = list(held[:count])
    return [label if s < received else kept[s] for s in range(max(received, len(kept)))]


def describe_held(labels: Sequence[str], home_at_seq0: bool) -> str:
    """'home (seq 0), new items 1-2 and its old items 3-11' of `labels` per seq ("new",
    "old", anything else: neither)."""
    if not labels:
        return "no items"
    parts = []
    start = 0
    if home_at_seq0:
        parts.append("home (seq 0)")
        start = 1
    words = {"new": "new item", "old": "its old item"}
    groups: list[tuple[str, list[int]]] = []
    for seq in range(start, len(labels)):
        label = labels[seq] if labels[seq] in words else "other"
        if groups and groups[-1][0] == label:
            groups[-1][1].append(seq)
        else:
            groups.append((label, [seq]))
    for label, seqs in groups:
        word = words.get(label, "item")
        plural = "s" if len(seqs) > 1 else ""
        tail = " of neither mission" if label == "other" else ""
        parts.append(f"{word}{plural} {_ranges(seqs)}{tail}")
    return parts[0] if len(parts) == 1 else ", ".join(parts[:-1]) + " and " + parts[-1]


def label_held(held: Sequence[MissionItem], old: Sequence[MissionItem],
               new: Sequence[MissionItem], expected: Sequence[str]) -> list[str]:
    """Each seq of a mission read back as "new" or "old" (by its item; one equal to both
    as `expected` says, ArduPilot's rule), else "other"."""
    out = []
    for seq, it in enumerate(held):
        is_new = seq < len(new) and same_item(it, new[seq])
        is_old = seq < len(old) and same_item(it, old[seq])
        if is_new and is_old:
            out.append(expected[seq] if seq < len(expected) else "new")
        else:
            out.append("new" if is_new else "old" if is_old else "other")
    return out
