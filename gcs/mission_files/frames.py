"""A mission's positions in the global or the local frame, through the vehicle's home
(`gcs mission download --frame`)."""

from __future__ import annotations

from collections.abc import Sequence

from common.wire.mission_items import HomePosition, MissionItem, to_global, to_local
from gcs.mission_files.items import MissionFileError


def to_frame(items: Sequence[MissionItem], frame: str | None,
             home: HomePosition | None) -> list[MissionItem]:
    """The items with their positions in "global" (MAV_FRAME_GLOBAL_RELATIVE_ALT: lat, lon
    in degrees, altitude above home) or "local" (MAV_FRAME_LOCAL_NED) frames, through the
    vehicle's home (`common.wire.mission_items.to_global` / `to_local`); None: as they are.
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
