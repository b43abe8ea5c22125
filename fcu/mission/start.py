"""The mission's plan at its start: the job (`fcu.work`; pure, picklable in and out); the
records of a mode change under way (a mission's start, POSCTL's fit)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

from common.wire.mav_enums import MAV_CMD, MAV_FRAME, MAV_RESULT
from common.wire.mission_items import MissionItem
from common.wire.modes import Mode
from fcu.control.dualquat import Quat, Vec3
from fcu.envelope.feasibility import envelope
from fcu.mission.executor import MissionExecutor
from fcu.mission.limits import MissionLimits
from fcu.mission.segments import Move
from fcu.modes.answer import Answer, Reply
from fcu.stages import Reference


@dataclass(eq=False, kw_only=True)
class UnderWay:
    """A mode change whose work runs beside the loop: every command waiting on it (one
    station's, or several asking for the same mode) is told its final answer, kept in
    `result`."""

    replies: list[Reply] = field(default_factory=list)
    result: Answer | None = None

    def on_end(self, reply: Reply) -> None:
        """`reply` told the final answer (at once if it is known)."""
        if self.result is not None:
            reply(*self.result)
        else:
            self.replies.append(reply)

    def end(self, result: MAV_RESULT, text: str) -> None:
        """The final answer, told to every command waiting on it."""
        self.result = Answer(result, text)
        for reply in self.replies:
            reply(result, text)
        self.replies.clear()


@dataclass(eq=False, kw_only=True)
class PosctlFit(UnderWay):
    """POSCTL's entry under way (`fcu.modes.commander`): its limits being fitted, from
    `previous`."""

    previous: Mode
    mode: Mode = Mode.POSCTL


@dataclass(eq=False, kw_only=True)
class MissionPlan(UnderWay):
    """A mission's start under way (`fcu.modes.commander`): from item `seq`, planned at `t_s` from
    `start`; `said` when it flies, `text` its command's answer."""

    seq: int
    t_s: float
    start: Reference
    said: str
    text: str
    mode: Mode = Mode.MISSION


def plan_from(items: Sequence[MissionItem], limits: MissionLimits, seq: int, t_s: float,
              p_enu_m: Vec3, q_enu_flu: Quat) -> tuple[MissionExecutor | None, str]:
    """The mission planned from item `seq` at `t_s` from the pose given, checked again with
    the upload's envelope (`MissionExecutor.refusal`): (the executor, '') or (None, why
    it does not fit from there). The executor comes without its segments' envelope
    scalings (`MissionExecutor.drop_scalings`): the loop takes it in between two steps."""
    executor = MissionExecutor(items, limits)
    executor.set_current(seq, t_s, p_enu_m, q_enu_flu)
    refused = executor.refusal()
    if refused:
        return None, refused
    executor.drop_scalings()
    return executor, ""


def warm(limits: MissionLimits) -> None:
    """Plan a take-off, a turning keyframe and a figure once from the start pose, check
    them again (`MissionExecutor.refusal`), search and explain a fast leg's envelope
    (`TimeScaling.stretches`, `shortest`, `excess`), and drop them, so that neither the
    first plan flown (TAKEOFF's, RTL's, LAND's: made in the loop's thread) nor the first
    mission checked pays for loading the planner's kernels (28 ms against 0.4 ms after for
    the take-off, measured on the tilted vehicle)."""
    if limits.vehicle is None:
        return
    local, nan = MAV_FRAME.MAV_FRAME_LOCAL_NED, float("nan")
    items = (MissionItem(0, local, MAV_CMD.MAV_CMD_NAV_TAKEOFF, 1, 1, 0.0, 0.0, 0.0, nan, 0,
                         0, -1.0),
             MissionItem(1, local, MAV_CMD.MAV_CMD_WAYPOINT_USER_1, 0, 1, 10.0, 0.1, 0.0,
                         0.5, 0, 0, -1.0),
             MissionItem(2, local, MAV_CMD.MAV_CMD_WAYPOINT_USER_2, 0, 1, 0.5, 30.0, 0.0,
                         0.0, 0, 0, -0.5))
    for plan in (items[:1], items):
        executor = MissionExecutor(plan, limits)
        executor.start(0.0, (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))
        executor.refusal()
    leg = Move(0, 0.0, (0.0, 0.0, 0.0), (5.0, 0.0, 1.0), (1.0, 0.0, 0.0, 0.0), None, 1.0, 0.0)
    scaling = envelope(limits.vehicle).scaling(leg)
    scaling.stretches(1.0)
    scaling.shortest()
    scaling.excess(1.0)
