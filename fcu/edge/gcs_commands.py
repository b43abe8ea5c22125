"""The FCU's commands from ground stations: COMMAND_LONG and COMMAND_INT executed and
acknowledged (COMMAND_ACK), each refusal explained by STATUSTEXT, and a retry answered without
executing the command again (`fcu.edge.gcs_server` dispatches them here).

A command whose work runs beside the control loop (a mission's start, POSCTL:
`fcu.modes.commander`) is answered with its final result when the work is done, as the command
protocol says. Work done within IN_PROGRESS_FIRST_S gets that answer alone, as PX4 and
ArduPilot answer a mode change: MAVSDK's mission plugins report an IN_PROGRESS as their final
result (Busy), though the mode is then entered. Longer work is acknowledged
MAV_RESULT_IN_PROGRESS after IN_PROGRESS_FIRST_S, then again every IN_PROGRESS_REPEAT_S (MAVSDK
re-sends a command, then gives it up, when nothing follows its IN_PROGRESS within its retries'
time, 1.5 s at its defaults). A retry meanwhile is answered IN_PROGRESS, never executed again;
the same mode asked for meanwhile (another station) waits for the same end; a newer command
that supersedes it ends it MAV_RESULT_FAILED, with why.

Parameters are range-checked against what they can mean (a mode's numbers, a mission item,
a message id); MAV_CMD_NAV_TAKEOFF's altitude is AMSL in COMMAND_LONG's p7 (as PX4 reads it)
and in COMMAND_INT's z by its frame.
"""

from __future__ import annotations

import math
import struct
from typing import Any, Protocol

from common.wire.mav_enums import MAV_CMD, MAV_FRAME, MAV_MODE_FLAG, MAV_RESULT, MAV_SEVERITY
from common.wire.mavlink import MAV
from common.wire.mavlink_types import Message, as_message
from common.wire.mavlink_types.protocol import CommandInt, CommandLong
from common.wire.mission_items import HomePosition
from common.wire.modes import Mode, decode
from fcu.edge.telemetry import REQUESTABLE, Schedule
from fcu.modes.answer import Answer, Reply
from fcu.pipeline import Pipeline

M = MAV
ACCEPTED, DENIED = MAV_RESULT.MAV_RESULT_ACCEPTED, MAV_RESULT.MAV_RESULT_DENIED
IN_PROGRESS = MAV_RESULT.MAV_RESULT_IN_PROGRESS
UNSUPPORTED = MAV_RESULT.MAV_RESULT_UNSUPPORTED
FAILED = MAV_RESULT.MAV_RESULT_FAILED
WARNING = MAV_SEVERITY.MAV_SEVERITY_WARNING
FORCE_DISARM_MAGIC = 21196.0  # MAV_CMD_COMPONENT_ARM_DISARM p2 that forces a disarm
MAX_PEERS = 64  # senders remembered for their retries (as parsers: one per link and peer)
RETRY_WINDOW_S = 5.0  # a COMMAND_LONG with confirmation > 0 this soon after is a retry
IN_PROGRESS_FIRST_S = 0.25  # work done sooner is answered once, with its final result
IN_PROGRESS_REPEAT_S = 0.5  # then a command under way is acknowledged IN_PROGRESS this often
ALWAYS_REQUESTABLE = (M.MAVLINK_MSG_ID_MISSION_CURRENT, M.MAVLINK_MSG_ID_HEARTBEAT,
                      M.MAVLINK_MSG_ID_SYS_STATUS)
# NAV_TAKEOFF's altitude: COMMAND_LONG p7 is AMSL (as PX4 reads it); COMMAND_INT's z by frame
_AMSL_FRAMES = (MAV_FRAME.MAV_FRAME_GLOBAL, MAV_FRAME.MAV_FRAME_GLOBAL_INT)
_RELATIVE_FRAMES = (MAV_FRAME.MAV_FRAME_GLOBAL_RELATIVE_ALT,
                    MAV_FRAME.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)


class Server(Protocol):
    """What the commands need of the ground-station server (`fcu.edge.gcs_server.GcsServer`)."""

    pipeline: Pipeline
    home: HomePosition

    def send(self, msg: Any, index: int | None = None) -> None: ...

    def say(self, severity: int, text: str | bytes, index: int | None = None) -> None: ...

    def send_message(self, msg_id: int, index: int | None = None) -> None: ...

    def schedule(self, index: int) -> Schedule: ...

    def set_mission_current(self, seq: int, reply: Reply | None = None) -> MAV_RESULT: ...


Command = CommandLong | CommandInt


def command_key(msg: Command) -> bytes:
    """A command's identity for retries: its id and parameters, bit for bit (NaN too)."""
    params: list[float]
    if msg.get_type() == "COMMAND_LONG":
        long = as_message(msg, CommandLong)
        params = [long.param1, long.param2, long.param3, long.param4, long.param5,
                  long.param6, long.param7]
    else:
        cint = as_message(msg, CommandInt)
        params = [cint.param1, cint.param2, cint.param3, cint.param4, cint.x, cint.y, cint.z,
                  cint.frame]
    return struct.pack("<I", msg.command) + struct.pack(f"<{len(params)}d", *params)


def as_int(x: float, lo: int, hi: int) -> int | None:
    """A float parameter as an integer in [lo, hi], or None."""
    if not math.isfinite(x) or x != round(x) or not lo <= x <= hi:
        return None
    return int(x)


class CommandService:
    """COMMAND_LONG / COMMAND_INT for one server: executed, acknowledged, retries answered."""

    def __init__(self, server: Server) -> None:
        self.server = server
        # The last command each sender had executed, for its retries (command protocol:
        # a re-send carries confirmation > 0 and is answered, never executed again).
        self.executed: dict[tuple[int, int, int], tuple[bytes, float, Answer]] = {}
        self.repeated_commands = 0
        # commands answered IN_PROGRESS and not yet ended: (link, command, when last told)
        self.under_way: dict[tuple[tuple[int, int, int], bytes], tuple[int, Command, float]] = {}

    def ack(self, index: int, msg: Message, command: int, result: int) -> None:
        """COMMAND_ACK to the sender; `progress` UINT8_MAX with IN_PROGRESS (the spec's
        "progress unknown"), else 0."""
        progress = 255 if result == IN_PROGRESS else 0
        self.server.send(M.MAVLink_command_ack_message(
            command, result, progress, 0, msg.get_srcSystem(), msg.get_srcComponent()), index)

    def handle(self, index: int, msg: Command, now_s: float) -> None:
        """Execute a COMMAND_LONG/INT and ACK it; a COMMAND_LONG re-sent by its sender
        (confirmation > 0, the same command and parameters, within RETRY_WINDOW_S of the
        first) gets the first answer again: a retry after a lost or late ACK must not start
        a mission, a landing or an RTL a second time, mid-flight."""
        sender = (index, msg.get_srcSystem(), msg.get_srcComponent())
        key = command_key(msg)
        last = self.executed.get(sender)
        retry = msg.get_type() == "COMMAND_LONG" and as_message(msg, CommandLong).confirmation > 0
        if retry and last is not None and last[0] == key and now_s - last[1] <= RETRY_WINDOW_S:
            self.repeated_commands += 1
            first = last[2]
            self.ack(index, msg, msg.command, first.result)
            if first.reason and first.result != ACCEPTED:
                self.server.say(WARNING, first.reason, index)
            return
        answer = self._execute(index, msg, now_s)
        if answer is None:
            return  # answered with its message (requests): a retry asks again
        plan = self.server.pipeline.commander.under_way
        if answer.result == IN_PROGRESS and plan is not None:  # answered when planned
            self._answer(index, msg, sender, key, now_s, Answer(IN_PROGRESS, ""), told=False)
            # told IN_PROGRESS IN_PROGRESS_FIRST_S from now if the work lasts (`tick`)
            self.under_way[(sender, key)] = (index, msg,
                                             now_s + IN_PROGRESS_FIRST_S - IN_PROGRESS_REPEAT_S)

            def ended(result: MAV_RESULT, text: str) -> None:
                self.under_way.pop((sender, key), None)
                self._answer(index, msg, sender, key, now_s, Answer(result, text), final=True)

            plan.on_end(ended)
            return
        self._answer(index, msg, sender, key, now_s, answer)

    def tick(self, now_s: float) -> None:
        """IN_PROGRESS to each command under way for IN_PROGRESS_FIRST_S, then again every
        IN_PROGRESS_REPEAT_S."""
        for entry, (index, msg, told_s) in list(self.under_way.items()):
            if now_s - told_s >= IN_PROGRESS_REPEAT_S:
                self.under_way[entry] = (index, msg, now_s)
                self.ack(index, msg, msg.command, IN_PROGRESS)

    def _answer(self, index: int, msg: Command, sender: tuple[int, int, int], key: bytes,
                now_s: float, answer: Answer, final: bool = False, told: bool = True) -> None:
        """ACK `answer` (where `told`) and keep it for the sender's retries; a `final` answer
        (of a command under way) only where that command is still the sender's last: a
        newer one's record is kept for its own retries."""
        if final:
            last = self.executed.get(sender)
            if last is not None and last[0] == key and last[1] == now_s:
                self.executed[sender] = (key, now_s, answer)
        else:
            if len(self.executed) >= MAX_PEERS and sender not in self.executed:
                del self.executed[next(iter(self.executed))]
            self.executed[sender] = (key, now_s, answer)
        if not told:
            return
        self.ack(index, msg, msg.command, answer.result)
        if answer.reason and answer.result != ACCEPTED:
            self.server.say(WARNING, answer.reason, index)

    def _execute(self, index: int, msg: Command, now_s: float) -> Answer | None:
        """A command's answer, or None when it was answered here."""
        cmd = msg.command
        p = (msg.param1, msg.param2, msg.param3, msg.param4)
        c = self.server.pipeline.commander
        if cmd == MAV_CMD.MAV_CMD_COMPONENT_ARM_DISARM:
            return self._arm_disarm(p)
        if cmd == MAV_CMD.MAV_CMD_DO_SET_MODE:
            return self._set_mode(p, now_s)
        if cmd == MAV_CMD.MAV_CMD_MISSION_START:
            first = as_int(p[0], 0, 0xFFFF) if p[0] != 0 else 0
            return Answer(DENIED, f"no mission item {p[0]:g}") if first is None else \
                c.mission_start(first)
        if cmd == MAV_CMD.MAV_CMD_DO_SET_MISSION_CURRENT:  # p1 -1: the current item
            seq = c.mission_current if p[0] == -1 else as_int(p[0], 0, 0xFFFF)
            if seq is None or not 0 <= seq < len(c.mission):  # the spec's answer: FAILED
                return Answer(FAILED, f"no mission item {p[0]:g}")
            return Answer(self.server.set_mission_current(seq), f"mission item {seq}")
        if cmd == MAV_CMD.MAV_CMD_NAV_LAND:
            return c.set_mode(Mode.LAND, now_s)
        if cmd == MAV_CMD.MAV_CMD_NAV_TAKEOFF:
            return self._takeoff(msg)
        if cmd == MAV_CMD.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            return c.set_mode(Mode.RTL, now_s)
        if cmd == MAV_CMD.MAV_CMD_SET_MESSAGE_INTERVAL:
            return self._set_interval(index, p)
        if cmd in (MAV_CMD.MAV_CMD_GET_MESSAGE_INTERVAL, MAV_CMD.MAV_CMD_REQUEST_MESSAGE,
                   MAV_CMD.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES):
            return self._send_requested(index, msg, p)
        return Answer(UNSUPPORTED, "")

    def _arm_disarm(self, p: tuple[float, float, float, float]) -> Answer:
        """MAV_CMD_COMPONENT_ARM_DISARM: p1 1 arms, 0 disarms (p2 the magic: forced)."""
        pipe = self.server.pipeline
        if p[0] == 1.0:
            return pipe.arm()
        if p[0] == 0.0:
            return pipe.commander.disarm(force=p[1] == FORCE_DISARM_MAGIC)
        return Answer(DENIED, "arm: p1 must be 0 or 1")

    def _set_mode(self, p: tuple[float, float, float, float], now_s: float) -> Answer:
        """MAV_CMD_DO_SET_MODE: base mode with the custom flag, main and sub mode."""
        base = as_int(p[0], 0, 255)
        main = as_int(p[1], 0, 255)
        sub = as_int(p[2], 0, 255) if math.isfinite(p[2]) else 0
        mode = decode(main, sub or 0) if base is not None and main is not None and \
            base & MAV_MODE_FLAG.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED else None
        if mode is None:
            return Answer(DENIED, "unsupported mode")
        return self.server.pipeline.commander.set_mode(mode, now_s)

    def _set_interval(self, index: int, p: tuple[float, float, float, float]) -> Answer:
        """MAV_CMD_SET_MESSAGE_INTERVAL: a message's rate on the link `index`."""
        msg_id = as_int(p[0], 0, 0xFFFFFF)
        if msg_id is None:
            return Answer(DENIED, f"no message id {p[0]:g}")
        ok, text = self.server.schedule(index).set_interval(msg_id, p[1])
        return Answer(ACCEPTED if ok else DENIED, text)

    def _send_requested(self, index: int, msg: Command,
                        p: tuple[float, float, float, float]) -> Answer | None:
        """MAV_CMD_GET_MESSAGE_INTERVAL, MAV_CMD_REQUEST_MESSAGE and
        MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: acknowledged and the message sent here
        (None), or refused (GET_MESSAGE_INTERVAL: an answer)."""
        cmd = msg.command
        if cmd == MAV_CMD.MAV_CMD_GET_MESSAGE_INTERVAL:
            msg_id = as_int(p[0], 0, 0xFFFF)
            if msg_id is None:
                return Answer(DENIED, f"no message id {p[0]:g}")
            self.ack(index, msg, cmd, ACCEPTED)
            self.server.send(M.MAVLink_message_interval_message(
                msg_id, self.server.schedule(index).interval_us(msg_id)), index)
            return None
        msg_id = M.MAVLINK_MSG_ID_AUTOPILOT_VERSION if cmd != MAV_CMD.MAV_CMD_REQUEST_MESSAGE \
            else as_int(p[0], 0, 0xFFFFFF)
        if msg_id is None or (msg_id not in REQUESTABLE and msg_id not in ALWAYS_REQUESTABLE):
            self.ack(index, msg, cmd, UNSUPPORTED)
            return None
        self.ack(index, msg, cmd, ACCEPTED)
        self.server.send_message(msg_id, index)
        return None

    def _takeoff(self, msg: Command) -> Answer:
        """MAV_CMD_NAV_TAKEOFF: altitude NaN (MAVSDK's, QGC's) -> MIS_TAKEOFF_ALT above the
        vehicle; else the altitude AMSL (COMMAND_LONG p7, as PX4; COMMAND_INT z in a global
        frame) or above home (COMMAND_INT z in a relative-altitude frame)."""
        c = self.server.pipeline.commander
        if msg.get_type() == "COMMAND_INT":
            cint = as_message(msg, CommandInt)
            alt, frame = cint.z, cint.frame
        else:
            alt, frame = as_message(msg, CommandLong).param7, MAV_FRAME.MAV_FRAME_GLOBAL
        if math.isnan(alt):
            return c.takeoff()
        if not math.isfinite(alt):
            return Answer(DENIED, "takeoff: altitude not finite")
        if frame in _AMSL_FRAMES:
            return c.takeoff(alt - self.server.home.alt_m)
        if frame in _RELATIVE_FRAMES:
            return c.takeoff(alt)
        return Answer(DENIED, f"takeoff: frame {frame} not supported")
