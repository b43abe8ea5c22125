"""The one place that imports pymavlink: MAVLink 2, `common` dialect, pinned here.

pymavlink picks MAVLink 1 or 2 from the environment at import time; setting MAVLINK20 before
the first import and importing the v2.0 dialect module directly makes the choice explicit.
"""

from __future__ import annotations

import os

os.environ["MAVLINK20"] = "1"

from pymavlink.dialects.v20 import common as mavlink

MAV = mavlink
MAV_COMP_ID_AUTOPILOT1 = mavlink.MAV_COMP_ID_AUTOPILOT1
MAV_COMP_ID_MISSIONPLANNER = mavlink.MAV_COMP_ID_MISSIONPLANNER
GCS_SYSID = 255
MAV_CMD_POSE_KEYFRAME = mavlink.MAV_CMD_WAYPOINT_USER_1  # 31000, DESIGN.md section 3
MAV_CMD_FIGURE_EIGHT = mavlink.MAV_CMD_WAYPOINT_USER_2  # 31001


class _Sink:
    """A file-like that keeps nothing: encoders here return bytes, links send them."""

    def write(self, _data: bytes) -> None:
        return None


def encoder(system_id: int, component_id: int) -> mavlink.MAVLink:
    """A MAVLink 2 encoder/decoder with its own sequence counter (one per sender)."""
    mav = mavlink.MAVLink(_Sink(), srcSystem=system_id, srcComponent=component_id,
                          use_native=False)
    mav.robust_parsing = True
    return mav


def parser() -> mavlink.MAVLink:
    """A decoder for one incoming byte stream (one per link and peer)."""
    return encoder(0, 0)


def pack(mav: mavlink.MAVLink, msg: mavlink.MAVLink_message) -> bytes:
    """Encode a message with `mav`'s identity and next sequence number (as MAVLink.send)."""
    data = msg.pack(mav)
    mav.seq = (mav.seq + 1) % 256
    return data
