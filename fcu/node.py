"""`fcu`: the flight controller as a process, a MAVLink 2 autopilot on its GCS links and the
lockstep partner of a simulator on its simulator link.

One thread, one `select` over all links. Lockstep: each ODOMETRY from the simulator is one
control period; it is answered with HIL_ACTUATOR_CONTROLS echoing its `time_usec`, and a
state already answered gets the stored answer again, without stepping the controller,
integral, unwrap or mission (so loss changes timing, never results). Before the flight
starts (armed and MISSION/OFFBOARD/LAND, or MISSION_START) states are not answered, so
simulated time stands still. Real time: a fixed-rate loop on the monotonic clock uses the
newest state. Everything people see (heartbeat, telemetry, mission progress) and every link
timeout runs on the monotonic wall clock.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import select
import signal
import struct
import sys
import time
from pathlib import Path

from common.binlog import LogWriter
from common.config import ConfigError, load_gains, load_vehicle
from common.frames import frd_to_flu, ned_to_enu, q_ned_frd_to_enu_flu
from common.links import Link, LinkError, open_link
from common.mavlink import (
    MAV,
    SigningKeyError,
    encoder,
    pack,
    parser,
    read_signing_key,
    signing_timestamp,
)
from common.modes import Mode, decode, decode_custom
from common.simlink import (
    LOCKSTEP_FLAG,
    MODE_ARMED,
    ODOMETRY_ID,
    ActuatorControls,
    FrameReader,
    pack_actuator_controls,
    unpack_odometry,
)
from fcu.core import ONBOARD_COLUMNS, onboard_row
from fcu.dualquat import q_angle, q_conj, q_mul, q_rotate
from fcu.mission import MissionLimits
from fcu.mission_protocol import MissionServer
from fcu.params import SPECS, ParamError, ParamStore
from fcu.telemetry import REQUESTABLE, Builders, Home, Schedule, autopilot_version, heartbeat
from fcu.telemetry import sys_status as sys_status_msg
from fcu.tracker import VehicleState
from fcu.vehicle import FORCE_DISARM_MAGIC, Failsafes, Vehicle

M = MAV
COMPONENT = M.MAV_COMP_ID_AUTOPILOT1
DEFAULT_GCS = ("udpout:127.0.0.1:14550", "udpout:127.0.0.1:14540")
HOUSEKEEPING_S = 0.002
MAX_POSITION_M = 1e6  # a state farther from the origin is refused as invalid
MAX_RATE = 1e4  # m/s and rad/s: a state moving faster is refused as invalid
SPIN_S = 0.002  # lockstep: poll instead of sleeping this long after each state


class FlightController:
    def __init__(self, vehicle: Vehicle, sim_url: str, gcs_urls: list[str], *, system_id: int,
                 lockstep: bool, home: Home, onboard_log: Path | None,
                 stats_path: Path | None, signing_key: bytes | None = None) -> None:
        self.vehicle = vehicle
        self.system_id = system_id
        self.lockstep = lockstep
        self.sim = open_link(sim_url, role="sim_client", system_id=system_id)
        self.sim_reader = FrameReader(self.sim.is_stream)
        self.gcs: list[Link] = [open_link(u, role="vehicle", system_id=system_id)
                                for u in gcs_urls]
        self.mav = encoder(system_id, COMPONENT)  # GCS links: one sequence for all of them
        self.signing_key = signing_key
        self.signing_rejects = 0
        self._stream_timestamps: dict = {}  # replay protection shared by every GCS parser
        if signing_key is not None:
            self.mav.signing.secret_key = signing_key
            self.mav.signing.sign_outgoing = True
            self.mav.signing.timestamp = signing_timestamp()
        self.sim_mav = encoder(system_id, COMPONENT)
        self.parsers: dict[tuple[int, object], MAV.MAVLink] = {}
        self.params = ParamStore(vehicle.gains)
        self.schedule = Schedule.default()
        self.builders = Builders(self._telemetry_source, home)
        self.missions = MissionServer(system_id, COMPONENT, vehicle.limits)
        self.missions.on_mission_changed = self._mission_changed
        self.missions.on_set_current = self._mission_set_current
        self.log = LogWriter(onboard_log, ONBOARD_COLUMNS) if onboard_log else None
        self.stats_path = stats_path
        self.w_max = vehicle.config.rotor_speed_max_rad_s
        self.period_us = 1_000_000 // vehicle.control_rate_hz
        self.running = True
        self.boot_s = time.monotonic()
        self.time_us = 0  # the FCU's clock: simulated in lockstep, monotonic in real time
        self.answered_us = -1
        self.answer = b""
        self.sim_seq = 0
        self.steps = 0
        self.resent_answers = 0
        self.deadline_misses = 0
        self.rejected_bytes = 0
        self.ignored_messages = 0
        self.gcs_seen_s = -math.inf
        self.v_enu = (0.0, 0.0, 0.0)
        self.last_mission_current_sent: tuple[int, int] | None = None
        self.sim_heartbeat_due = 0.0
        self.last_sim_rx_s = -math.inf
        self.last_state_s: float | None = None

    # ------------------------------------------------------------------ sending

    def send(self, msg: MAV.MAVLink_message) -> None:
        data = pack(self.mav, msg)
        for link in self.gcs:
            link.send(data)

    def say(self, severity: int, text: str) -> None:
        self.send(M.MAVLink_statustext_message(severity, text.encode()[:50], 0, 0))

    def _ack(self, msg, command: int, result: int) -> None:
        self.send(M.MAVLink_command_ack_message(command, result, 0, 0, msg.get_srcSystem(),
                                                msg.get_srcComponent()))

    # ------------------------------------------------------------------ simulator link

    def _on_sim_datagram(self, peer: object, data: bytes) -> None:
        self.last_sim_rx_s = time.monotonic()
        frames, rejected = self.sim_reader.feed(peer, data)
        self.rejected_bytes += rejected
        for f in frames:
            if f.msg_id != ODOMETRY_ID:
                continue  # HIL_SENSOR and others: for estimators to come
            if f.sysid != self.system_id:
                self.ignored_messages += 1  # another vehicle's simulator: not our state
                continue
            odo = unpack_odometry(f.payload)
            if odo.time_usec == self.answered_us:
                self.sim.send(self.answer)  # the same answer, nothing stepped again
                self.resent_answers += 1
                self.last_state_s = self.last_sim_rx_s
                continue
            if odo.time_usec < self.answered_us:
                self.ignored_messages += 1  # stale
                continue
            values = (*odo.p_ned_m, *odo.q_ned_frd, *odo.v_frd_m_s, *odo.omega_frd_rad_s)
            q_norm = math.sqrt(sum(c * c for c in odo.q_ned_frd))
            if not all(math.isfinite(v) for v in values) or abs(q_norm - 1.0) > 0.01 or \
                    max(abs(c) for c in odo.p_ned_m) > MAX_POSITION_M or \
                    max(abs(c) for c in (*odo.v_frd_m_s, *odo.omega_frd_rad_s)) > MAX_RATE:
                # Not a state a vehicle can be in: refused and counted. A stream of them is
                # state loss, which the failsafe of COM_STATE_LOSS_T handles.
                self.ignored_messages += 1
                continue
            q = q_ned_frd_to_enu_flu(odo.q_ned_frd)
            state = VehicleState(ned_to_enu(odo.p_ned_m), q, frd_to_flu(odo.v_frd_m_s),
                                 frd_to_flu(odo.omega_frd_rad_s))
            self.vehicle.on_state(odo.time_usec, state)
            self.last_state_s = self.last_sim_rx_s  # a valid state of ours: input alive
            self.v_enu = q_rotate(self.vehicle.state.q_enu_flu, state.v_flu_m_s)
            if self.lockstep:
                self.time_us = odo.time_usec
                if self.vehicle.flight_started:
                    self._control_step(odo.time_usec)

    def _control_step(self, t_us: int) -> None:
        """Step at the FCU's time t_us; answer and log under the state's own stamp (equal to
        t_us in lockstep), so that logs join with the simulator's on time_usec."""
        t0 = time.perf_counter()
        out = self.vehicle.step(t_us)
        stamp = max(self.vehicle.state_time_us, 0)
        step_us = (time.perf_counter() - t0) * 1e6
        n = len(out.speed_rad_s)
        controls = (*(s / self.w_max for s in out.speed_rad_s), *out.tilt_rad,
                    *(0.0,) * (16 - 2 * n))
        self.sim_seq = (self.sim_seq + 1) & 0xFF
        self.answer = pack_actuator_controls(
            ActuatorControls(stamp, controls, MODE_ARMED if out.armed else 0,
                             LOCKSTEP_FLAG if self.lockstep else 0),
            self.sim_seq, self.system_id, COMPONENT)
        if self.lockstep:
            self.answered_us = stamp
        self.sim.send(self.answer)
        self.steps += 1
        if self.log is not None and out.result is not None:
            self.log.write(onboard_row(stamp, self.vehicle.state, out.result, out.speed_rad_s,
                                       out.tilt_rad, out.armed, step_us))

    # ------------------------------------------------------------------ GCS links

    def _on_gcs_datagram(self, index: int, peer: object, data: bytes) -> None:
        key = (index, peer)
        p = self.parsers.get(key)
        if p is None:
            p = self.parsers[key] = parser()
            if self.signing_key is not None:
                p.signing.secret_key = self.signing_key  # unsigned frames are refused
                p.signing.stream_timestamps = self._stream_timestamps
        try:
            msgs = p.parse_buffer(data) or []
        except Exception:  # pymavlink raises on some malformed input; count and go on
            self.rejected_bytes += len(data)
            msgs = []
        if not self.gcs[index].is_stream and p.buf_len():
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
            try:
                self._handle(msg)
            except (ValueError, TypeError, OverflowError) as exc:
                self.ignored_messages += 1
                self.say(M.MAV_SEVERITY_WARNING, f"rejected {msg.get_type()}: {exc}"[:50])

    def _for_us(self, msg) -> bool:
        target = getattr(msg, "target_system", 0)
        return target in (0, self.system_id)

    def _handle(self, msg) -> None:
        kind = msg.get_type()
        now = time.monotonic()
        if kind == "HEARTBEAT":
            if msg.type == M.MAV_TYPE_GCS:
                self.gcs_seen_s = now
            return
        if not self._for_us(msg):
            self.ignored_messages += 1
            return
        if kind in ("COMMAND_LONG", "COMMAND_INT"):
            try:
                self._command(msg, now)
            except (ValueError, OverflowError, TypeError) as exc:  # e.g. NaN where an int is due
                self.ignored_messages += 1
                self._ack(msg, msg.command, M.MAV_RESULT_DENIED)
                self.say(M.MAV_SEVERITY_WARNING, f"command {msg.command} denied: {exc}")
        elif kind.startswith("MISSION_"):
            for reply in self.missions.handle(msg, now):
                self.send(reply)
        elif kind == "PARAM_REQUEST_LIST":
            for i in range(len(SPECS)):
                self._send_param(i)
        elif kind == "PARAM_REQUEST_READ":
            self._param_read(msg)
        elif kind == "PARAM_SET":
            self._param_set(msg)
        elif kind == "SET_POSITION_TARGET_LOCAL_NED":
            ok, why = self.vehicle.offboard_position(
                now, msg.coordinate_frame, msg.type_mask, (msg.x, msg.y, msg.z),
                (msg.vx, msg.vy, msg.vz), (msg.afx, msg.afy, msg.afz), msg.yaw)
            if not ok:
                self.say(M.MAV_SEVERITY_WARNING, why)
        elif kind == "SET_ATTITUDE_TARGET":
            ok, why = self.vehicle.offboard_attitude(
                now, msg.type_mask, tuple(msg.q),
                (msg.body_roll_rate, msg.body_pitch_rate, msg.body_yaw_rate))
            if not ok:
                self.say(M.MAV_SEVERITY_WARNING, why)
        elif kind == "SET_MODE":
            mode = decode_custom(msg.custom_mode)
            if mode is not None:
                self.vehicle.set_mode(mode, now)

    def _command(self, msg, now: float) -> None:
        cmd = msg.command
        p = (msg.param1, msg.param2, msg.param3, msg.param4)
        v = self.vehicle
        result = M.MAV_RESULT_ACCEPTED
        text = ""
        if cmd == M.MAV_CMD_COMPONENT_ARM_DISARM:
            if p[0] == 1.0:
                result, text = v.arm()
            elif p[0] == 0.0:
                result, text = v.disarm(force=p[1] == FORCE_DISARM_MAGIC)
            else:
                result, text = M.MAV_RESULT_DENIED, "arm: p1 must be 0 or 1"
        elif cmd == M.MAV_CMD_DO_SET_MODE:
            mode = decode(int(p[1]), int(p[2])) if int(p[0]) & \
                M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED and math.isfinite(p[1]) else None
            if mode is None:
                result, text = M.MAV_RESULT_DENIED, "unsupported mode"
            else:
                result, text = v.set_mode(mode, now)
        elif cmd == M.MAV_CMD_MISSION_START:
            first = int(p[0]) if math.isfinite(p[0]) else 0
            result, text = v.mission_start(first)
        elif cmd == M.MAV_CMD_DO_SET_MISSION_CURRENT:
            seq = int(p[0]) if math.isfinite(p[0]) else -1
            result = M.MAV_RESULT_ACCEPTED if self._mission_set_current(seq) \
                else M.MAV_RESULT_DENIED
            text = f"no mission item {seq}"
        elif cmd == M.MAV_CMD_NAV_LAND:
            result, text = v.set_mode(Mode.LAND, now) if v.armed else (
                M.MAV_RESULT_DENIED, "land: not armed")
        elif cmd == M.MAV_CMD_SET_MESSAGE_INTERVAL:
            ok = math.isfinite(p[0]) and self.schedule.set_interval(int(p[0]), p[1])
            result = M.MAV_RESULT_ACCEPTED if ok else M.MAV_RESULT_DENIED
        elif cmd == M.MAV_CMD_GET_MESSAGE_INTERVAL:
            msg_id = int(p[0]) if math.isfinite(p[0]) else -1
            if not 0 <= msg_id <= 0xFFFF:
                self._ack(msg, cmd, M.MAV_RESULT_DENIED)
                self.say(M.MAV_SEVERITY_WARNING, f"no message id {p[0]:g}")
                return
            self._ack(msg, cmd, M.MAV_RESULT_ACCEPTED)
            self.send(M.MAVLink_message_interval_message(
                msg_id, int(self.schedule.interval_us(msg_id))))
            return
        elif cmd in (M.MAV_CMD_REQUEST_MESSAGE, M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES):
            msg_id = M.MAVLINK_MSG_ID_AUTOPILOT_VERSION if cmd != M.MAV_CMD_REQUEST_MESSAGE \
                else (int(p[0]) if math.isfinite(p[0]) else -1)
            if msg_id not in REQUESTABLE and msg_id not in (
                    M.MAVLINK_MSG_ID_MISSION_CURRENT, M.MAVLINK_MSG_ID_HEARTBEAT):
                self._ack(msg, cmd, M.MAV_RESULT_UNSUPPORTED)
                return
            self._ack(msg, cmd, M.MAV_RESULT_ACCEPTED)
            self._send_message(msg_id)
            return
        else:
            result = M.MAV_RESULT_UNSUPPORTED
        self._ack(msg, cmd, result)
        if text and result != M.MAV_RESULT_ACCEPTED:
            self.say(M.MAV_SEVERITY_WARNING, text)

    # ------------------------------------------------------------------ parameters

    def _send_param(self, index: int) -> None:
        name = SPECS[index].name
        self.send(M.MAVLink_param_value_message(name.encode(), self.params.values[name],
                                                M.MAV_PARAM_TYPE_REAL32, len(SPECS), index))

    def _param_read(self, msg) -> None:
        name = msg.param_id if isinstance(msg.param_id, str) else msg.param_id.decode()
        name = name.rstrip("\x00")
        if msg.param_index >= 0:
            if msg.param_index < len(SPECS):
                self._send_param(msg.param_index)
            return
        if name in self.params.values:
            self._send_param(self.params.index(name))

    def _param_set(self, msg) -> None:
        name = msg.param_id if isinstance(msg.param_id, str) else msg.param_id.decode()
        name = name.rstrip("\x00")
        if name not in self.params.values:
            self.say(M.MAV_SEVERITY_WARNING, f"unknown parameter {name}")
            return
        try:
            self.params.set(name, float(msg.param_value))
        except ParamError as exc:
            self.say(M.MAV_SEVERITY_WARNING, str(exc))
        else:
            self._apply_params()
        self._send_param(self.params.index(name))  # the value now in force

    def _apply_params(self) -> None:
        v = self.params.values
        self.vehicle.core.tracker.set_gains(self.params.gains())
        self.vehicle.offboard_timeout_s = v["COM_OF_LOSS_T"]
        self.vehicle.failsafes = Failsafes(
            gcs_loss_s=v["COM_DL_LOSS_T"], gcs_loss_land_s=v["COM_DL_LAND_T"],
            state_loss_s=v["COM_STATE_LOSS_T"], saturation_s=v["COM_SAT_T"],
            saturation_hold=v["COM_SAT_ACT"] == 1.0, divergence_m=v["COM_DIV_POS"])
        limits = MissionLimits(max_distance_m=v["GF_MAX_DIST"],
                               cruise_speed_m_s=v["MIS_CRUISE_SPD"],
                               land_speed_m_s=v["MIS_LAND_SPD"],
                               takeoff_speed_m_s=v["MIS_TKO_SPD"])
        self.vehicle.limits = limits
        self.missions.limits = limits

    # ------------------------------------------------------------------ missions

    def _mission_changed(self, items) -> None:
        self.vehicle.set_mission(tuple(items))

    def _mission_set_current(self, seq: int) -> bool:
        result, _ = self.vehicle.set_mission_current(seq)
        if result == M.MAV_RESULT_ACCEPTED:
            self.missions.current_seq = seq
            self._send_message(M.MAVLINK_MSG_ID_MISSION_CURRENT)  # the spec's confirmation
        return result == M.MAV_RESULT_ACCEPTED

    def _mission_current_msg(self):
        v = self.vehicle
        total = len(v.mission)
        if not total:
            state = M.MISSION_STATE_NO_MISSION
        elif v.mission_done:
            state = M.MISSION_STATE_COMPLETE
        elif v.mission_running:
            state = M.MISSION_STATE_ACTIVE
        else:
            state = M.MISSION_STATE_NOT_STARTED
        seq = total if v.mission_done else v.mission_current
        return M.MAVLink_mission_current_message(seq, total, state, 0)

    # ------------------------------------------------------------------ telemetry

    def _telemetry_source(self) -> dict:
        v = self.vehicle
        ref = v.last_ref
        errors = None
        if v.state is not None and ref is not None and v.armed:
            p, pd = v.state.p_enu_m, ref.p_enu_m
            errors = (math.dist(p, pd), q_angle(q_mul(q_conj(ref.q_enu_flu),
                                                      v.state.q_enu_flu)))
        return {"time_us": self.time_us, "state": v.state, "ref": ref, "errors": errors,
                "output": v.last_output, "v_enu": self.v_enu, "landed": v.landed}

    def _send_message(self, msg_id: int) -> None:
        v = self.vehicle
        if msg_id == M.MAVLINK_MSG_ID_HEARTBEAT:
            msg = heartbeat(v.armed, v.mode.custom_mode, v.armed, v.failsafe)
        elif msg_id == M.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            msg = autopilot_version(self.system_id)
        elif msg_id == M.MAVLINK_MSG_ID_SYS_STATUS:
            msg = sys_status_msg(v.state is not None and not v.failsafe, 0,
                                 self.rejected_bytes + self.ignored_messages,
                                 self.signing_rejects)
        elif msg_id == M.MAVLINK_MSG_ID_MISSION_CURRENT:
            msg = self._mission_current_msg()
            self.last_mission_current_sent = (msg.seq, msg.mission_state)
        else:
            msg = self.builders.build(msg_id)
        for m in msg if isinstance(msg, list) else [msg]:
            if m is None:
                continue
            try:
                self.send(m)
            except (struct.error, OverflowError, ValueError):
                self.ignored_messages += 1  # a value the wire cannot carry: skip, keep flying

    def _housekeeping(self, now: float) -> None:
        v = self.vehicle
        if self.sim_heartbeat_due == 0.0:
            self._apply_params()  # the failsafe and mission settings of the parameters
        if now >= self.sim_heartbeat_due:
            # Simulators learn where we are from this, as from PX4's first packets.
            self.sim.send(pack(self.sim_mav, heartbeat(v.armed, v.mode.custom_mode, v.armed)))
            self.sim_heartbeat_due = now + 1.0
        v.check_links(now, self.gcs_seen_s,
                      self.last_state_s if self.last_state_s is not None else now)
        for reply in self.missions.tick(now):
            self.send(reply)
        for severity, text in v.messages:
            self.say(severity, text)
        v.messages.clear()
        for ev in v.mission_events:
            if ev.kind == "reached":
                self.send(M.MAVLink_mission_item_reached_message(ev.seq))
        if v.mission_events:
            self.missions.current_seq = v.mission_current
            self._send_message(M.MAVLINK_MSG_ID_MISSION_CURRENT)  # on change
        v.mission_events.clear()
        for msg_id in self.schedule.pop_due(now):
            self._send_message(msg_id)

    # ------------------------------------------------------------------ loop

    def run(self) -> None:
        try:
            self._loop()
        finally:
            self.close()

    def _loop(self) -> None:
        period_s = self.period_us * 1e-6
        next_tick = time.monotonic()
        next_housekeeping = next_tick
        links = [("sim", 0, self.sim), *(("gcs", i, link) for i, link in enumerate(self.gcs))]
        while self.running:
            fds = {fd: entry for entry in links for fd in entry[2].filenos()}
            now = time.monotonic()
            wake = self.schedule.next_due()
            if not self.lockstep:
                wake = min(wake, next_tick)
            timeout = min(max(0.0, wake - now), 0.05)
            if self.lockstep and self.sim.spin and now - self.last_sim_rx_s < SPIN_S:
                timeout = 0.0  # lockstep: the next state is microseconds away, poll for it
            try:
                readable, _, _ = select.select(list(fds), [], [], timeout)
            except InterruptedError:
                continue
            if not readable and timeout == 0.0:
                os.sched_yield()  # polling: let a process that has work run on this core
            for kind, index, link in {fds[fd] for fd in readable}:
                for peer, data in link.recv():
                    if kind == "sim":
                        self._on_sim_datagram(peer, data)
                    else:
                        self._on_gcs_datagram(index, peer, data)
            now = time.monotonic()
            if not self.lockstep and now >= next_tick:
                late = now - next_tick
                if late > 0.5 * period_s:
                    self.deadline_misses += 1
                skipped = int(late // period_s)
                self.deadline_misses += skipped
                next_tick += (skipped + 1) * period_s
                self.time_us = round((now - self.boot_s) * 1e6)
                self._control_step(self.time_us)
            v = self.vehicle
            if now >= next_housekeeping or v.messages or v.mission_events:
                # Link-facing work at most every few ms: the lockstep path stays lean.
                self._housekeeping(now)
                next_housekeeping = now + HOUSEKEEPING_S

    def close(self) -> None:
        if self.log is not None:
            self.log.close()
            self.log = None
        if self.stats_path is not None:
            stats = {"steps": self.steps, "deadline_misses": self.deadline_misses,
                     "signing_rejects": self.signing_rejects,
                     "resent_answers": self.resent_answers,
                     "rejected_bytes": self.rejected_bytes,
                     "ignored_messages": self.ignored_messages,
                     "mission_completed": self.vehicle.mission_done,
                     "lockstep": self.lockstep}
            tmp = self.stats_path.with_suffix(".tmp")
            tmp.write_text(json.dumps(stats, indent=2) + "\n")
            os.replace(tmp, self.stats_path)
        for link in (self.sim, *self.gcs):
            link.close()


def _home(text: str) -> Home:
    try:
        lat, lon, alt = (float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected LAT,LON,ALT, got {text}") from None
    if not (-90 <= lat <= 90 and -180 <= lon <= 180 and math.isfinite(alt)):
        raise argparse.ArgumentTypeError(f"home out of range: {text}")
    return Home(lat, lon, alt)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="fcu", description="dual-quaternion flight controller")
    p.add_argument("--vehicle", type=Path, required=True, help="vehicle TOML")
    p.add_argument("--gains", type=Path, required=True, help="gains TOML (PID or PD)")
    p.add_argument("--sim", default="udpout:127.0.0.1:4560", help="simulator link URL")
    p.add_argument("--gcs", action="append", metavar="URL",
                   help=f"GCS link URL, repeatable (default: {' and '.join(DEFAULT_GCS)})")
    p.add_argument("--rate", type=int, default=500, help="control rate in Hz (1..1000)")
    p.add_argument("--realtime", action="store_true", help="run on the monotonic clock")
    p.add_argument("--sysid", type=int, default=1, help="MAVLink system id (1..254)")
    p.add_argument("--home", type=_home, default=Home(), help="LAT,LON,ALT of the origin")
    p.add_argument("--onboard-log", type=Path, help="write the onboard log here")
    p.add_argument("--stats", type=Path, help="write run statistics (JSON) here at exit")
    p.add_argument("--signing-key", metavar="FILE",
                   help="MAVLink 2 signing on the GCS links: sign telemetry, refuse unsigned "
                        "or wrongly signed input (key from `gcs keygen`)")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        if not 1 <= args.rate <= 1000:
            raise ConfigError(f"--rate: expected 1..1000 Hz, got {args.rate}")
        if not 1 <= args.sysid <= 254:
            raise ConfigError(f"--sysid: expected 1..254, got {args.sysid}")
        vehicle = Vehicle(load_vehicle(args.vehicle), load_gains(args.gains), args.rate)
        key = read_signing_key(args.signing_key) if args.signing_key else None
        fc = FlightController(vehicle, args.sim, args.gcs or list(DEFAULT_GCS),
                              system_id=args.sysid, lockstep=not args.realtime,
                              home=args.home, onboard_log=args.onboard_log,
                              stats_path=args.stats, signing_key=key)
    except (ConfigError, LinkError, SigningKeyError) as exc:
        print(f"fcu: {exc}", file=sys.stderr)
        return 2

    def stop(_signum, _frame):
        fc.running = False

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    links = ", ".join(args.gcs or DEFAULT_GCS)
    print(f"fcu: system {args.sysid}, simulator {args.sim}, GCS {links} "
          f"({'real time' if args.realtime else 'lockstep'}, {args.rate} Hz)", flush=True)
    sim_port = getattr(fc.sim, "local_port", None)
    if sim_port is not None:
        print(f"fcu: sim port {sim_port}", flush=True)
    fc.run()
    print(f"fcu: stopped after {fc.steps} control steps; {fc.deadline_misses} deadline misses, "
          f"{fc.resent_answers} answers re-sent, {fc.rejected_bytes} bytes rejected", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
