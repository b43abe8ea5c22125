"""Mission files: the plain-text `QGC WPL 110` (MAVProxy's `wp load` / `wp save`; QGC reads
it), QGroundControl's JSON `.plan`, and a readable TOML form for 6-DoF keyframes and the
figure-infinity.

All map onto `MissionItem` (MISSION_ITEM_INT fields). In QGC WPL and `.plan`, x and y are
written as floats in the frame's unit (metres in local frames, degrees in global ones); in
MissionItem local x, y are int32 in 1e-4 m and global ones in 1e-7 deg
(`common.wire.mission_items.xy_scale`, the scaling of the legacy MISSION_ITEM too). Floats are
written with Python's shortest round-trip representation, so a file written from downloaded
items reads back to the same items.

Latitudes and longitudes are written a quarter of MISSION_ITEM_INT's 1e-7 deg step away from
zero from the item's integer (47.3977421 as 47.397742125): MAVProxy (`int(x * 1e7)`) and QGC
(an implicit double-to-int conversion) truncate when they upload, and a value written exactly
on the step reads back one step short about one time in sixteen (1.1 cm north); from a
quarter step, truncation and rounding both give the item's integer, and a file read here
(rounding) gives the same items. The written position is within 3 mm of the item's.

ArduPilot keeps its home at mission seq 0 (`gcs.vehicle_link.mission_home`): a `.plan` holds it in
`plannedHomePosition`, the TOML form in an optional `[home]` table (lat_deg, lon_deg, alt_m
AMSL), and a WPL file for ArduPilot as line 0 (MAVProxy's convention). `read_mission_doc`
gives the items with the file's home; `format_mission` writes the home where the format
keeps it when the vehicle counts home in its mission (`home_at_seq0`).

MAVProxy scales x and y by 1e7 in every frame, local ones included (where MAVLink takes
1e4): a local-frame WPL file does not survive `wp load`. Write missions for MAVProxy in a
global frame (`gcs mission download --frame global`, `to_frame`).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from common.process.cliargs import read_text_file
from common.wire.mission_items import HomePosition, MissionItem
from gcs.mission_files.items import MissionDoc, MissionFileError
from gcs.mission_files.plan import (
    MAV_AUTOPILOT_PX4,
    MAV_TYPE_HEXAROTOR,
    format_plan,
    parse_plan_doc,
)
from gcs.mission_files.toml import format_toml, parse_toml_doc
from gcs.mission_files.wpl import format_wpl, parse_wpl
from gcs.vehicle_link.mission_home import with_home

FORMATS = ("plan", "wpl", "toml")
# File formats by extension; others (.txt among them) are read by their content and
# written as WPL.
EXTENSIONS = {".plan": "plan", ".waypoints": "wpl", ".toml": "toml"}


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
    apart from its lines: `gcs.vehicle_link.mission_home.for_ardupilot` reads line 0)."""
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
