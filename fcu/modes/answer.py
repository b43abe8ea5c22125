"""A command's answer: its MAV_RESULT and why, the reason said once (the station is sent it as
a STATUSTEXT when the result is not ACCEPTED: `fcu.edge.gcs_commands`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

from common.wire.mav_enums import MAV_RESULT


class Answer(NamedTuple):
    result: MAV_RESULT
    reason: str


Reply = Callable[[MAV_RESULT, str], None]  # a command's final answer, when it comes later
