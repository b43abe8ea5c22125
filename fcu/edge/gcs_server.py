"""The FCU's ground-station side: parse (and check signatures of) what GCS links send,
dispatch commands, parameters, missions and offboard set-points into the pipeline, and send
telemetry, each link on its own schedule.

One error boundary for everything a GCS sends: no value of any field of any message ends
the process or leaves a stream unbounded. Requests are range-checked against what the
answer can carry, a SET_MESSAGE_INTERVAL changes only the link it came on, and each link's
streams together stay within its message budget (`fcu.edge.telemetry.LINK_BUDGET_MSG_S`); every
refusal is explained by STATUSTEXT. An exception that still reaches the boundary is counted
in `internal_errors` and reported, never raised.

Commands are executed in `fcu.edge.gcs_commands`, parameters served by `fcu.edge.gcs_params`,
offboard and manual set-points decoded by `fcu.edge.setpoint_wire`; telemetry is built by
`fcu.edge.telemetry`.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable
from dataclasses import dataclass, field

from common.links import Link
from common.outcome import Event
from common.wire.mav_enums import MAV_COMPONENT, MAV_RESULT, MAV_SEVERITY, MAV_TYPE, MISSION_STATE
from common.wire.mavlink import MAV, encoder, pack, parser, signed_parser, signing_timestamp
from common.wire.mavlink_types import as_message
from common.wire.mavlink_types.protocol import (
    CommandInt,
    CommandLong,
    ManualControl,
    ParamRequestRead,
    ParamSet,
    SetAttitudeTarget,
    SetMode,
    SetPositionTargetLocalNed,
)
from common.wire.mavlink_types.state import Heartbeat
from common.wire.mission_items import HomePosition
from common.wire.modes import decode_custom
from fcu.control.dualquat import q_angle, q_conj, q_mul, q_rotate
from fcu.edge.gcs_commands import MAX_PEERS, CommandService
from fcu.edge.gcs_params import ParamService
from fcu.edge.mission_protocol import MissionServer
from fcu.edge.setpoint_wire import (
    SetpointRefused,
    attitude_target,
    position_target,
    sticks_from_manual_control,
)
from fcu.edge.telemetry import (
    Builders,
    Schedule,
    Snapshot,
    autopilot_version,
    heartbeat,
    sys_status,
)
from fcu.modes.answer import Reply
from fcu.params import ParamStore
from fcu.pipeline import Pipeline
from fcu.safety.failsafe import Failsafe

M = MAV
WARNING = MAV_SEVERITY.MAV_SEVERITY_WARNING
COMPONENT = MAV_COMPONENT.MAV_COMP_ID_AUTOPILOT1
STATUSTEXT_LEN = 50
MAX_PARSERS = MAX_PEERS  # one per (link, peer); peers cycling source ports cannot grow it
MAX_PARTNERS = MAX_PEERS  # mission partners whose link is kept (`mission_partner_links`)
STATUSTEXT_BURST = 20.0
STATUSTEXT_RATE = 10.0  # per second and link
# Every message type a ground station can send that the server acts on (the rest are
# ignored); the dispatch property test and the fuzz campaign send each of them.
HANDLED = ("HEARTBEAT", "COMMAND_LONG", "COMMAND_INT", "MISSION_COUNT", "MISSION_ITEM_INT",
           "MISSION_ITEM", "MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_REQUEST_LIST",
           "MISSION_CLEAR_ALL", "MISSION_ACK", "MISSION_SET_CURRENT",
           "MISSION_WRITE_PARTIAL_LIST", "MISSION_REQUEST_PARTIAL_LIST",
           "PARAM_REQUEST_LIST", "PARAM_REQUEST_READ", "PARAM_SET",
           "SET_POSITION_TARGET_LOCAL_NED", "SET_ATTITUDE_TARGET", "SET_MODE",
           "MANUAL_CONTROL")


@dataclass
class GcsLink:
    """One ground-station link: its transport, encoder (sequence, signing) and streams."""

    link: Link
    mav: MAV.MAVLink
    schedule: Schedule = field(default_factory=Schedule.default)
    text_tokens: float = 20.0  # STATUSTEXT budget (see GcsServer.say)
    text_refill_s: float = 0.0


class GcsServer:
    def __init__(self, links: list[Link], pipeline: Pipeline, params: ParamStore,
                 missions: MissionServer, *, system_id: int, home: HomePosition,
                 signing_key: bytes | None = None,
                 on_params: Callable[[], None] | None = None) -> None:
        self.pipeline = pipeline
        self.params = params
        self.missions = missions
        self.system_id = system_id
        self.signing_key = signing_key
        self.links = [GcsLink(link, self._encoder(i)) for i, link in enumerate(links)]
        self.parsers: dict[tuple[int, object], MAV.MAVLink] = {}
        # replay protection shared by every parser: (link id, system, component) -> timestamp
        self._stream_timestamps: dict[tuple[int, int, int], int] = {}
        self.home = home
        self.builders = Builders(self.snapshot, home)
        self.gcs_seen_s = -math.inf
        self.mission_link = 0  # the link of the latest mission upload (re-requests go there)
        # the link each GCS (system, component) last sent a mission message on: where the
        # answers that come later (`MissionServer.outbox`) go
        self.mission_partner_links: dict[tuple[int, int], int] = {}
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
        self.commands = CommandService(self)
        self.param_service = ParamService(params, self.send, self.say, lambda: pipeline.armed,
                                          on_params)

    def _encoder(self, index: int) -> MAV.MAVLink:
        mav = encoder(self.system_id, COMPONENT)
        if self.signing_key is not None:
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

    def say(self, severity: int, text: str | bytes, index: int | None = None,
            text_id: int = 0, chunk_seq: int = 0) -> None:
        """STATUSTEXT to one link (an answer to what it sent) or to all (the vehicle's own
        news); each link takes at most STATUSTEXT_BURST in a row, refilled at
        STATUSTEXT_RATE per second, so a peer cannot turn its refusals into a flood.
        `text_id`, `chunk_seq`: a chunk of a longer text (MAVLink 2), sent as it is."""
        raw = text.encode() if isinstance(text, str) else text
        if self.on_text is not None:
            self.on_text(severity, raw[:STATUSTEXT_LEN].decode(errors="replace"))
        self._text(severity, raw, index, text_id, chunk_seq)

    def _text(self, severity: int, raw: bytes, index: int | None, text_id: int = 0,
              chunk_seq: int = 0) -> None:
        msg = M.MAVLink_statustext_message(severity, raw[:STATUSTEXT_LEN], text_id, chunk_seq)
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
            self.say(MAV_SEVERITY.MAV_SEVERITY_ERROR,
                     f"internal error on {msg.get_type()}: {type(exc).__name__}", index)

    def _handle(self, index: int, msg: MAV.MAVLink_message, now_s: float) -> None:
        kind = msg.get_type()
        if kind == "HEARTBEAT":
            if as_message(msg, Heartbeat).type == MAV_TYPE.MAV_TYPE_GCS:
                self.gcs_seen_s = now_s
            return
        if kind == "MANUAL_CONTROL":  # its target field is `target`
            self._manual(msg, now_s)
            return
        # for this system and its autopilot (0: all), as PX4's receiver judges a target: a
        # command or set-point for a camera or a companion computer is not the vehicle's
        target = getattr(msg, "target_system", 0)
        component = getattr(msg, "target_component", 0)
        if target not in (0, self.system_id) or component not in (0, COMPONENT):
            self.ignored_messages += 1
            return
        if kind == "COMMAND_LONG":
            self.commands.handle(index, as_message(msg, CommandLong), now_s)
        elif kind == "COMMAND_INT":
            self.commands.handle(index, as_message(msg, CommandInt), now_s)
        elif kind.startswith("MISSION_"):
            self._mission(index, msg, now_s)
        elif kind.startswith("PARAM_"):
            self._param(index, msg)
        elif kind in ("SET_POSITION_TARGET_LOCAL_NED", "SET_ATTITUDE_TARGET"):
            self._setpoint(index, msg, now_s)
        elif kind == "SET_MODE":
            self._set_mode(index, msg, now_s)

    def _manual(self, msg: MAV.MAVLink_message, now_s: float) -> None:
        """MANUAL_CONTROL for this system (or all): the sticks to the commander."""
        manual = as_message(msg, ManualControl)
        if manual.target not in (0, self.system_id):
            self.ignored_messages += 1
            return
        self.pipeline.commander.manual_input(
            now_s, sticks_from_manual_control(manual.x, manual.y, manual.z, manual.r))

    def _mission(self, index: int, msg: MAV.MAVLink_message, now_s: float) -> None:
        """A mission protocol message: the mission server's replies to the link it came on
        (an upload's re-requests too, once it began there)."""
        partners = self.mission_partner_links
        partner = (msg.get_srcSystem(), msg.get_srcComponent())
        partners.pop(partner, None)  # kept newest last, the oldest forgotten past MAX_PARTNERS
        partners[partner] = index
        if len(partners) > MAX_PARTNERS:
            del partners[next(iter(partners))]
        replies = self.missions.handle(msg, now_s)
        if msg.get_type() == "MISSION_COUNT" and any(r.get_type() == "MISSION_REQUEST_INT"
                                                     for r in replies):
            self.mission_link = index  # an upload began: its re-requests go here
        self._send_mission(replies, index)

    def _param(self, index: int, msg: MAV.MAVLink_message) -> None:
        """PARAM_REQUEST_LIST, PARAM_REQUEST_READ and PARAM_SET to the parameter service."""
        kind = msg.get_type()
        if kind == "PARAM_REQUEST_LIST":
            self.param_service.request_list(index)
        elif kind == "PARAM_REQUEST_READ":
            self.param_service.param_read(index, as_message(msg, ParamRequestRead))
        elif kind == "PARAM_SET":
            self.param_service.param_set(index, as_message(msg, ParamSet))

    def _set_mode(self, index: int, msg: MAV.MAVLink_message, now_s: float) -> None:
        """SET_MODE: a known custom mode to the commander; a refusal said to the link (a
        mode under way: when it ends)."""
        mode = decode_custom(as_message(msg, SetMode).custom_mode)
        if mode is None:
            return
        cmd = self.pipeline.commander
        result, text = cmd.set_mode(mode, now_s)
        under_way = cmd.under_way
        if result == MAV_RESULT.MAV_RESULT_IN_PROGRESS and under_way is not None:
            under_way.on_end(lambda r, t: self._refused(r, t, index))
        else:
            self._refused(result, text, index)

    def _refused(self, result: int, text: str, index: int) -> None:
        if result != MAV_RESULT.MAV_RESULT_ACCEPTED and text:
            self.say(WARNING, text, index)

    def _send_mission(self, replies: list[MAV.MAVLink_message], index: int | None) -> None:
        for reply in replies:
            if reply.get_type() == "STATUSTEXT":
                # within the link's budget, a chunk with its id (put back together)
                self.say(reply.severity, reply.text, index, reply.id, reply.chunk_seq)
                continue
            self.send(reply, index)

    def _setpoint(self, index: int, msg: MAV.MAVLink_message, now_s: float) -> None:
        """An offboard target decoded (`fcu.edge.setpoint_wire`) and given to the commander; a
        refusal, by the wire or by the commander, is said to the link it came on."""
        cmd = self.pipeline.commander
        try:
            if msg.get_type() == "SET_POSITION_TARGET_LOCAL_NED":
                pos = as_message(msg, SetPositionTargetLocalNed)
                ok, why = cmd.offboard_position(now_s, position_target(
                    pos.coordinate_frame, pos.type_mask, (pos.x, pos.y, pos.z),
                    (pos.vx, pos.vy, pos.vz), (pos.afx, pos.afy, pos.afz), pos.yaw,
                    pos.yaw_rate))
            else:
                att = as_message(msg, SetAttitudeTarget)
                ok, why = cmd.offboard_attitude(now_s, attitude_target(
                    att.type_mask, att.q,
                    (att.body_roll_rate, att.body_pitch_rate, att.body_yaw_rate)))
        except SetpointRefused as exc:
            ok, why = False, str(exc)
        if not ok:
            self.say(WARNING, why, index)

    # ------------------------------------------------------------------ commands

    @property
    def repeated_commands(self) -> int:
        """Retried commands answered without executing them again."""
        return self.commands.repeated_commands

    def schedule(self, index: int) -> Schedule:
        """The streams of link `index`."""
        return self.links[index].schedule

    def set_mission_current(self, seq: int, reply: Reply | None = None) -> MAV_RESULT:
        """MAV_RESULT of a new current item; IN_PROGRESS while the mission is planned again
        from it beside the loop (MISSION_CURRENT, then `reply`, when it is)."""
        c = self.pipeline.commander
        result, _ = c.set_mission_current(seq)

        def confirmed(result: MAV_RESULT, text: str) -> None:
            if result == MAV_RESULT.MAV_RESULT_ACCEPTED:
                self.send_message(M.MAVLINK_MSG_ID_MISSION_CURRENT)  # the spec's confirmation
            elif text:
                self.say(WARNING, text)
            if reply is not None:
                reply(result, text)

        if result == MAV_RESULT.MAV_RESULT_IN_PROGRESS and c.modes.mission_run.plan is not None:
            c.modes.mission_run.plan.on_end(confirmed)
        elif result == MAV_RESULT.MAV_RESULT_ACCEPTED:
            self.send_message(M.MAVLINK_MSG_ID_MISSION_CURRENT)
        return result

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
            state = MISSION_STATE.MISSION_STATE_NO_MISSION
        elif c.mission_done:
            state = MISSION_STATE.MISSION_STATE_COMPLETE
        elif c.modes.mission_run.running:
            state = MISSION_STATE.MISSION_STATE_ACTIVE
        else:
            state = MISSION_STATE.MISSION_STATE_NOT_STARTED
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
            state_ok = pipe.state is not None and pipe.failsafe != Failsafe.STATE_LOST
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
        # the upload's answer once its check is done (`fcu.work`), each to its GCS's link;
        # then re-requests
        for partner, reply in self.missions.take_outbox():
            self._send_mission([reply], self.mission_partner_links.get(partner,
                                                                       self.mission_link))
        self.commands.tick(now_s)  # IN_PROGRESS again for the commands under way
        self.param_service.tick()  # a parameter list, a burst at a time
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
