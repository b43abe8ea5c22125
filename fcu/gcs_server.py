"""The FCU's ground-station side: parse (and check signatures of) what GCS links send,
dispatch commands, parameters, missions and offboard set-points into the pipeline, and send
telemetry, each link on its own schedule.

One error boundary for everything a GCS sends: no value of any field of any message ends
the process or leaves a stream unbounded. Requests are range-checked against what the
answer can carry, a SET_MESSAGE_INTERVAL changes only the link it came on, and each link's
streams together stay within its message budget (`fcu.telemetry.LINK_BUDGET_MSG_S`); every
refusal is explained by STATUSTEXT. An exception that still reaches the boundary is counted
in `internal_errors` and reported, never raised.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable
from dataclasses import dataclass, field

from common.links import Link
from common.mavlink import MAV, encoder, pack, parser, signed_parser
from common.modes import Mode, decode, decode_custom
from common.outcome import Event
from fcu.commander import FORCE_DISARM_MAGIC
from fcu.dualquat import q_angle, q_conj, q_mul, q_rotate
from fcu.mission_protocol import MissionServer
from fcu.params import SPECS, ParamError, ParamStore
from fcu.pipeline import Pipeline
from fcu.telemetry import (
    REQUESTABLE,
    Builders,
    Home,
    Schedule,
    Snapshot,
    autopilot_version,
    heartbeat,
    sys_status,
)

M = MAV
COMPONENT = M.MAV_COMP_ID_AUTOPILOT1
STATUSTEXT_LEN = 50
MAX_PARSERS = 64  # one per (link, peer); peers cycling source ports cannot grow it
STATUSTEXT_BURST = 20.0
STATUSTEXT_RATE = 10.0  # per second and link
RETRY_WINDOW_S = 5.0  # a COMMAND_LONG with confirmation > 0 this soon after is a retry
# Every message type a ground station can send that the server acts on (the rest are
# ignored); the dispatch property test and the fuzz campaign send each of them.
HANDLED = ("HEARTBEAT", "COMMAND_LONG", "COMMAND_INT", "MISSION_COUNT", "MISSION_ITEM_INT",
           "MISSION_ITEM", "MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_REQUEST_LIST",
           "MISSION_CLEAR_ALL", "MISSION_ACK", "MISSION_SET_CURRENT",
           "MISSION_WRITE_PARTIAL_LIST", "MISSION_REQUEST_PARTIAL_LIST",
           "PARAM_REQUEST_LIST", "PARAM_REQUEST_READ", "PARAM_SET",
           "SET_POSITION_TARGET_LOCAL_NED", "SET_ATTITUDE_TARGET", "SET_MODE",
           "MANUAL_CONTROL")
_ALWAYS_REQUESTABLE = (M.MAVLINK_MSG_ID_MISSION_CURRENT, M.MAVLINK_MSG_ID_HEARTBEAT,
                       M.MAVLINK_MSG_ID_SYS_STATUS)
# NAV_TAKEOFF's altitude: COMMAND_LONG p7 is AMSL (as PX4 reads it); COMMAND_INT's z by frame
_AMSL_FRAMES = (M.MAV_FRAME_GLOBAL, M.MAV_FRAME_GLOBAL_INT)
_RELATIVE_FRAMES = (M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)


@dataclass
class GcsLink:
    """One ground-station link: its transport, encoder (sequence, signing) and streams."""

    link: Link
    mav: MAV.MAVLink
    schedule: Schedule = field(default_factory=Schedule.default)
    text_tokens: float = 20.0  # STATUSTEXT budget (see GcsServer.say)
    text_refill_s: float = 0.0


def _command_key(msg: MAV.MAVLink_message) -> bytes:
    """A command's identity for retries: its id and parameters, bit for bit (NaN too)."""
    params = [getattr(msg, f"param{i}") for i in range(1, 8)] if msg.get_type() == \
        "COMMAND_LONG" else [*(getattr(msg, f"param{i}") for i in range(1, 5)), msg.x, msg.y,
                             msg.z, msg.frame]
    return struct.pack("<I", msg.command) + struct.pack(f"<{len(params)}d", *params)


def _as_int(x: float, lo: int, hi: int) -> int | None:
    """A float parameter as an integer in [lo, hi], or None."""
    if not math.isfinite(x) or x != round(x) or not lo <= x <= hi:
        return None
    return int(x)


class GcsServer:
    def __init__(self, links: list[Link], pipeline: Pipeline, params: ParamStore,
                 missions: MissionServer, *, system_id: int, home: Home,
                 signing_key: bytes | None = None,
                 on_params: Callable[[], None] | None = None) -> None:
        self.pipeline = pipeline
        self.params = params
        self.missions = missions
        self.system_id = system_id
        self.signing_key = signing_key
        self.on_params = on_params
        self.links = [GcsLink(link, self._encoder(i)) for i, link in enumerate(links)]
        self.parsers: dict[tuple[int, object], MAV.MAVLink] = {}
        self._stream_timestamps: dict = {}  # replay protection shared by every parser
        self.home = home
        self.builders = Builders(self.snapshot, home)
        self.gcs_seen_s = -math.inf
        self.mission_link = 0  # the link of the latest mission upload (re-requests go there)
        missions.current = lambda: pipeline.commander.mission_current
        self.rejected_bytes = 0
        self.ignored_messages = 0
        self.signing_rejects = 0
        self.internal_errors = 0
        self.unsendable = 0
        self.texts_dropped = 0
        self.now_s = 0.0  # the wall clock at the latest input or tick
        self.time_us = 0  # the FCU's clock, for telemetry stamps
        # Told of every STATUSTEXT the vehicle says on its own account or in answer (not
        # the pipeline's events, which `announce` sends): the onboard log records them.
        self.on_text: Callable[[int, str], None] | None = None
        self.v_enu_m_s = (0.0, 0.0, 0.0)
        self.announced: tuple[bool, int] | None = None  # (armed, custom_mode) last sent
        # The last command each sender had executed, for its retries (command protocol:
        # a re-send carries confirmation > 0 and is answered, never executed again).
        self._executed: dict[tuple[int, int, int], tuple[bytes, float, int, str]] = {}
        self.repeated_commands = 0

    def _encoder(self, index: int) -> MAV.MAVLink:
        mav = encoder(self.system_id, COMPONENT)
        if self.signing_key is not None:
            from common.mavlink import signing_timestamp

            mav.signing.secret_key = self.signing_key
            mav.signing.sign_outgoing = True
            mav.signing.link_id = index & 0xFF
            mav.signing.timestamp = signing_timestamp()
        return mav

    # ------------------------------------------------------------------ sending

    def send(self, msg: MAV.MAVLink_message, index: int | None = None) -> None:
        """To one link (`index`) or to all; a message the wire cannot carry is skipped."""
        targets = self.links if index is None else [self.links[index]]
        for gl in targets:
            try:
                data = pack(gl.mav, msg)
            except (struct.error, OverflowError, ValueError, TypeError):
                self.unsendable += 1
                return
            gl.link.send(data)

    def say(self, severity: int, text: str | bytes, index: int | None = None) -> None:
        """STATUSTEXT to one link (an answer to what it sent) or to all (the vehicle's own
        news); each link takes at most STATUSTEXT_BURST in a row, refilled at
        STATUSTEXT_RATE per second, so a peer cannot turn its refusals into a flood."""
        raw = text.encode() if isinstance(text, str) else text
        if self.on_text is not None:
            self.on_text(severity, raw[:STATUSTEXT_LEN].decode(errors="replace"))
        self._text(severity, raw, index)

    def _text(self, severity: int, raw: bytes, index: int | None) -> None:
        msg = M.MAVLink_statustext_message(severity, raw[:STATUSTEXT_LEN], 0, 0)
        for i in (range(len(self.links)) if index is None else (index,)):
            gl = self.links[i]
            gl.text_tokens = min(STATUSTEXT_BURST, gl.text_tokens + STATUSTEXT_RATE * max(
                0.0, self.now_s - gl.text_refill_s))
            gl.text_refill_s = self.now_s
            if gl.text_tokens < 1.0:
                self.texts_dropped += 1
                continue
            gl.text_tokens -= 1.0
            self.send(msg, i)

    def announce(self, events: list[Event]) -> None:
        for ev in events:
            self._text(ev.severity, ev.text.encode(), None)

    def _ack(self, index: int, msg: MAV.MAVLink_message, command: int, result: int) -> None:
        self.send(M.MAVLink_command_ack_message(command, result, 0, 0, msg.get_srcSystem(),
                                                msg.get_srcComponent()), index)

    # ------------------------------------------------------------------ receiving

    def on_datagram(self, index: int, peer: object, data: bytes, now_s: float) -> None:
        key = (index, peer)
        p = self.parsers.pop(key, None)
        if p is None:
            if len(self.parsers) >= MAX_PARSERS:  # the least recently heard peer goes
                del self.parsers[next(iter(self.parsers))]
            p = parser() if self.signing_key is None else \
                signed_parser(self.signing_key, self._stream_timestamps)
        self.parsers[key] = p  # most recently heard last
        try:
            msgs = p.parse_buffer(data) or []
        except Exception:  # pymavlink raises on some malformed input; count and go on
            self.rejected_bytes += len(data)
            msgs = []
        if not self.links[index].link.is_stream and p.buf_len():
            # A datagram holds whole frames: a frame cut short must not be completed by the
            # bytes of the next datagram (pymavlink parses one stream per sender).
            self.rejected_bytes += p.buf_len()
            p.buf = bytearray()
            p.buf_index = 0
            p.expected_length = M.HEADER_LEN_V1 + 2
        for msg in msgs:
            if msg.get_type() == "BAD_DATA":
                if "signature" in str(getattr(msg, "reason", "")):
                    self.signing_rejects += 1
                else:
                    self.rejected_bytes += len(msg.get_msgbuf())
                continue
            self.handle(index, msg, now_s)

    def handle(self, index: int, msg: MAV.MAVLink_message, now_s: float) -> None:
        """The error boundary around one message from link `index`."""
        self.now_s = max(self.now_s, now_s)
        try:
            self._handle(index, msg, now_s)
        except Exception as exc:  # a bug, not an input error: count, report, keep flying
            self.internal_errors += 1
            self.ignored_messages += 1
            self.say(M.MAV_SEVERITY_ERROR,
                     f"internal error on {msg.get_type()}: {type(exc).__name__}", index)

    def _handle(self, index: int, msg: MAV.MAVLink_message, now_s: float) -> None:
        kind = msg.get_type()
        if kind == "HEARTBEAT":
            if msg.type == M.MAV_TYPE_GCS:
                self.gcs_seen_s = now_s
            return
        if kind == "MANUAL_CONTROL":  # its target field is `target`
            if msg.target not in (0, self.system_id):
                self.ignored_messages += 1
                return
            self.pipeline.commander.manual_input(now_s, msg.x, msg.y, msg.z, msg.r)
            return
        target = getattr(msg, "target_system", 0)
        if target not in (0, self.system_id):
            self.ignored_messages += 1
            return
        cmd = self.pipeline.commander
        if kind in ("COMMAND_LONG", "COMMAND_INT"):
            self._command(index, msg, now_s)
        elif kind.startswith("MISSION_"):
            for reply in self.missions.handle(msg, now_s):
                if reply.get_type() == "STATUSTEXT":
                    self.say(reply.severity, reply.text, index)  # within the link's budget
                    continue
                if reply.get_type() == "MISSION_REQUEST_INT" and kind == "MISSION_COUNT":
                    self.mission_link = index  # an upload began: its re-requests go here
                self.send(reply, index)
        elif kind == "PARAM_REQUEST_LIST":
            for i in range(len(SPECS)):
                self._send_param(i, index)
        elif kind == "PARAM_REQUEST_READ":
            self._param_read(index, msg)
        elif kind == "PARAM_SET":
            self._param_set(index, msg)
        elif kind == "SET_POSITION_TARGET_LOCAL_NED":
            ok, why = cmd.offboard_position(
                now_s, msg.coordinate_frame, msg.type_mask, (msg.x, msg.y, msg.z),
                (msg.vx, msg.vy, msg.vz), (msg.afx, msg.afy, msg.afz), msg.yaw)
            if not ok:
                self.say(M.MAV_SEVERITY_WARNING, why, index)
        elif kind == "SET_ATTITUDE_TARGET":
            ok, why = cmd.offboard_attitude(
                now_s, msg.type_mask, tuple(msg.q),
                (msg.body_roll_rate, msg.body_pitch_rate, msg.body_yaw_rate))
            if not ok:
                self.say(M.MAV_SEVERITY_WARNING, why, index)
        elif kind == "SET_MODE":
            mode = decode_custom(msg.custom_mode)
            if mode is not None:
                result, text = cmd.set_mode(mode, now_s)
                if result != M.MAV_RESULT_ACCEPTED and text:
                    self.say(M.MAV_SEVERITY_WARNING, text, index)

    # ------------------------------------------------------------------ commands

    def _command(self, index: int, msg: MAV.MAVLink_message, now_s: float) -> None:
        """Execute a COMMAND_LONG/INT and ACK it; a COMMAND_LONG re-sent by its sender
        (confirmation > 0, the same command and parameters, within RETRY_WINDOW_S of the
        first) gets the first answer again: a retry after a lost or late ACK must not start
        a mission, a landing or an RTL a second time, mid-flight."""
        sender = (index, msg.get_srcSystem(), msg.get_srcComponent())
        key = _command_key(msg)
        last = self._executed.get(sender)
        if getattr(msg, "confirmation", 0) > 0 and last is not None and last[0] == key \
                and now_s - last[1] <= RETRY_WINDOW_S:
            self.repeated_commands += 1
            self._ack(index, msg, msg.command, last[2])
            if last[3] and last[2] != M.MAV_RESULT_ACCEPTED:
                self.say(M.MAV_SEVERITY_WARNING, last[3], index)
            return
        result, text = self._execute(index, msg, now_s)
        if result is None:
            return  # answered with its message (requests): a retry asks again
        if len(self._executed) >= MAX_PARSERS and sender not in self._executed:
            del self._executed[next(iter(self._executed))]
        self._executed[sender] = (key, now_s, result, text)
        self._ack(index, msg, msg.command, result)
        if text and result != M.MAV_RESULT_ACCEPTED:
            self.say(M.MAV_SEVERITY_WARNING, text, index)

    def _execute(self, index: int, msg: MAV.MAVLink_message,
                 now_s: float) -> tuple[int | None, str]:
        """(MAV_RESULT, reason) of a command, or (None, "") when it was answered here."""
        cmd = msg.command
        p = (msg.param1, msg.param2, msg.param3, msg.param4)
        pipe = self.pipeline
        c = pipe.commander
        result, text = M.MAV_RESULT_ACCEPTED, ""
        if cmd == M.MAV_CMD_COMPONENT_ARM_DISARM:
            if p[0] == 1.0:
                result, text = pipe.arm()
            elif p[0] == 0.0:
                result, text = c.disarm(force=p[1] == FORCE_DISARM_MAGIC)
            else:
                result, text = M.MAV_RESULT_DENIED, "arm: p1 must be 0 or 1"
        elif cmd == M.MAV_CMD_DO_SET_MODE:
            base = _as_int(p[0], 0, 255)
            main = _as_int(p[1], 0, 255)
            sub = _as_int(p[2], 0, 255) if math.isfinite(p[2]) else 0
            mode = decode(main, sub or 0) if base is not None and main is not None and \
                base & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED else None
            if mode is None:
                result, text = M.MAV_RESULT_DENIED, "unsupported mode"
            else:
                result, text = c.set_mode(mode, now_s)
        elif cmd == M.MAV_CMD_MISSION_START:
            first = _as_int(p[0], 0, 0xFFFF) if p[0] != 0 else 0
            if first is None:
                result, text = M.MAV_RESULT_DENIED, f"no mission item {p[0]:g}"
            else:
                result, text = c.mission_start(first)
        elif cmd == M.MAV_CMD_DO_SET_MISSION_CURRENT:
            seq = _as_int(p[0], 0, 0xFFFF)
            ok = seq is not None and self.set_mission_current(seq)
            result = M.MAV_RESULT_ACCEPTED if ok else M.MAV_RESULT_DENIED
            text = f"no mission item {p[0]:g}"
        elif cmd == M.MAV_CMD_NAV_LAND:
            result, text = c.set_mode(Mode.LAND, now_s)
        elif cmd == M.MAV_CMD_NAV_TAKEOFF:
            result, text = self._takeoff(msg)
        elif cmd == M.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            result, text = c.set_mode(Mode.RTL, now_s)
        elif cmd == M.MAV_CMD_SET_MESSAGE_INTERVAL:
            msg_id = _as_int(p[0], 0, 0xFFFFFF)
            if msg_id is None:
                result, text = M.MAV_RESULT_DENIED, f"no message id {p[0]:g}"
            else:
                ok, text = self.links[index].schedule.set_interval(msg_id, p[1])
                result = M.MAV_RESULT_ACCEPTED if ok else M.MAV_RESULT_DENIED
        elif cmd == M.MAV_CMD_GET_MESSAGE_INTERVAL:
            msg_id = _as_int(p[0], 0, 0xFFFF)
            if msg_id is None:
                result, text = M.MAV_RESULT_DENIED, f"no message id {p[0]:g}"
            else:
                self._ack(index, msg, cmd, M.MAV_RESULT_ACCEPTED)
                self.send(M.MAVLink_message_interval_message(
                    msg_id, self.links[index].schedule.interval_us(msg_id)), index)
                return None, ""
        elif cmd in (M.MAV_CMD_REQUEST_MESSAGE, M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES):
            msg_id = M.MAVLINK_MSG_ID_AUTOPILOT_VERSION if cmd != M.MAV_CMD_REQUEST_MESSAGE \
                else _as_int(p[0], 0, 0xFFFFFF)
            if msg_id is None or (msg_id not in REQUESTABLE
                                  and msg_id not in _ALWAYS_REQUESTABLE):
                self._ack(index, msg, cmd, M.MAV_RESULT_UNSUPPORTED)
                return None, ""
            self._ack(index, msg, cmd, M.MAV_RESULT_ACCEPTED)
            self.send_message(msg_id, index)
            return None, ""
        else:
            result = M.MAV_RESULT_UNSUPPORTED
        return result, text

    def _takeoff(self, msg: MAV.MAVLink_message) -> tuple[int, str]:
        """MAV_CMD_NAV_TAKEOFF: altitude NaN (MAVSDK's, QGC's) -> MIS_TAKEOFF_ALT above the
        vehicle; else the altitude AMSL (COMMAND_LONG p7, as PX4; COMMAND_INT z in a global
        frame) or above home (COMMAND_INT z in a relative-altitude frame)."""
        c = self.pipeline.commander
        if msg.get_type() == "COMMAND_INT":
            alt, frame = msg.z, msg.frame
        else:
            alt, frame = msg.param7, M.MAV_FRAME_GLOBAL
        if math.isnan(alt):
            return c.takeoff()
        if not math.isfinite(alt):
            return M.MAV_RESULT_DENIED, "takeoff: altitude not finite"
        if frame in _AMSL_FRAMES:
            return c.takeoff(alt - self.home.alt_m)
        if frame in _RELATIVE_FRAMES:
            return c.takeoff(alt)
        return M.MAV_RESULT_DENIED, f"takeoff: frame {frame} not supported"

    def set_mission_current(self, seq: int) -> bool:
        result, _ = self.pipeline.commander.set_mission_current(seq)
        if result == M.MAV_RESULT_ACCEPTED:
            self.send_message(M.MAVLINK_MSG_ID_MISSION_CURRENT)  # the spec's confirmation
        return result == M.MAV_RESULT_ACCEPTED

    # ------------------------------------------------------------------ parameters

    def _send_param(self, i: int, index: int | None = None) -> None:
        name = SPECS[i].name
        self.send(M.MAVLink_param_value_message(name.encode(), self.params.values[name],
                                                M.MAV_PARAM_TYPE_REAL32, len(SPECS), i), index)

    @staticmethod
    def _param_name(msg: MAV.MAVLink_message) -> str:
        name = msg.param_id if isinstance(msg.param_id, str) else \
            msg.param_id.decode("ascii", "replace")
        return name.rstrip("\x00")

    def _param_read(self, index: int, msg: MAV.MAVLink_message) -> None:
        if msg.param_index >= 0:
            if msg.param_index < len(SPECS):
                self._send_param(msg.param_index, index)
            return
        name = self._param_name(msg)
        if name in self.params.values:
            self._send_param(self.params.index(name), index)

    def _param_set(self, index: int, msg: MAV.MAVLink_message) -> None:
        """A set in force is echoed (PARAM_VALUE) to every link. A refusal answers the link
        that asked: PARAM_ERROR first (MAVSDK reports its error code: DOES_NOT_EXIST,
        VALUE_OUT_OF_RANGE, instead of a timeout), a STATUSTEXT with the reason, and for a
        known parameter the unchanged value (PARAM_VALUE, what older clients wait for)."""
        name = self._param_name(msg)
        raw_id = msg.param_id.encode() if isinstance(msg.param_id, str) else msg.param_id
        if name not in self.params.values:
            self.send(M.MAVLink_param_error_message(
                msg.get_srcSystem(), msg.get_srcComponent(), raw_id[:16], -1,
                M.MAV_PARAM_ERROR_DOES_NOT_EXIST), index)
            self.say(M.MAV_SEVERITY_WARNING, f"unknown parameter {name}", index)
            return
        i = self.params.index(name)
        try:
            self.params.set(name, float(msg.param_value), armed=self.pipeline.armed)
        except ParamError as exc:
            self.send(M.MAVLink_param_error_message(
                msg.get_srcSystem(), msg.get_srcComponent(), name.encode(), i,
                M.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE), index)
            self.say(M.MAV_SEVERITY_WARNING, str(exc), index)
            self._send_param(i, index)  # the unchanged value
            return
        if self.on_params is not None:
            self.on_params()
        self._send_param(i)  # the value now in force, to every link

    # ------------------------------------------------------------------ telemetry

    def snapshot(self) -> Snapshot:
        pipe = self.pipeline
        c = pipe.commander
        ref, state = c.last_ref, pipe.state
        errors = None
        if state is not None and ref is not None and c.armed:
            errors = (math.dist(state.p_enu_m, ref.p_enu_m),
                      q_angle(q_mul(q_conj(ref.q_enu_flu), state.q_enu_flu)))
        v_enu = q_rotate(state.q_enu_flu, state.v_flu_m_s) if state is not None \
            else (0.0, 0.0, 0.0)
        return Snapshot(self.time_us, state, ref, errors, pipe.last_output, v_enu, c.landed,
                        pipe.estimator, pipe.pose_level > 0)

    def mission_current_msg(self) -> MAV.MAVLink_message:
        c = self.pipeline.commander
        total = len(c.mission)
        if not total:
            state = M.MISSION_STATE_NO_MISSION
        elif c.mission_done:
            state = M.MISSION_STATE_COMPLETE
        elif c.mission_running:
            state = M.MISSION_STATE_ACTIVE
        else:
            state = M.MISSION_STATE_NOT_STARTED
        seq = total if c.mission_done else c.mission_current
        return M.MAVLink_mission_current_message(min(seq, 0xFFFF), min(total, 0xFFFF), state, 0)

    def build(self, msg_id: int) -> list[MAV.MAVLink_message]:
        pipe = self.pipeline
        c = pipe.commander
        if msg_id == M.MAVLINK_MSG_ID_HEARTBEAT:
            msgs = heartbeat(c.armed, c.mode.custom_mode, c.armed, pipe.failsafe)
        elif msg_id == M.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            msgs = autopilot_version(self.system_id)
        elif msg_id == M.MAVLINK_MSG_ID_SYS_STATUS:
            state_ok = pipe.state is not None and pipe.failsafe != "state input lost"
            heard = c.sticks_received_s > -math.inf
            msgs = sys_status(state_ok=state_ok, control_ok=state_ok and not pipe.failsafe,
                              prearm_ok=state_ok and pipe.estimator_ready, load_permille=0,
                              manual_control=c.manual_fresh(self.now_s) if heard else None,
                              rejected=self.rejected_bytes + self.ignored_messages,
                              signing_rejects=self.signing_rejects)
        elif msg_id == M.MAVLINK_MSG_ID_MISSION_CURRENT:
            msgs = self.mission_current_msg()
        else:
            msgs = self.builders.build(msg_id)
        if msgs is None:
            return []
        return msgs if isinstance(msgs, list) else [msgs]

    def send_message(self, msg_id: int, index: int | None = None) -> None:
        for m in self.build(msg_id):
            self.send(m, index)

    def tick(self, now_s: float) -> None:
        """Wall-clock work: mission re-requests, each link's due streams; a HEARTBEAT at once
        when the mode or the arming state changes (on the links that have the stream on)."""
        self.now_s = max(self.now_s, now_s)
        for reply in self.missions.tick(now_s):
            self.send(reply, self.mission_link)
        c = self.pipeline.commander
        now = (c.armed, c.mode.custom_mode)
        if now != self.announced:
            hb_id = M.MAVLINK_MSG_ID_HEARTBEAT
            for gl in self.links:
                interval = gl.schedule.intervals.get(hb_id, 0.0)
                if self.announced is not None and interval > 0:
                    gl.schedule.due[hb_id] = now_s  # due now, then on its cadence again
            self.announced = now
        for i, gl in enumerate(self.links):
            for msg_id in gl.schedule.pop_due(now_s):
                self.send_message(msg_id, i)

    def next_due(self) -> float:
        return min((gl.schedule.next_due() for gl in self.links), default=math.inf)
