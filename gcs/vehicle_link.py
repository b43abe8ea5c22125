"""Ground-station actions on a connected vehicle, in standard MAVLink only, so that they work
against PX4 and ArduPilot for the standard parts: status, arming, modes, parameters,
offboard pose setpoints, recording.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

from common.mavlink import MAV
from common.modes import Mode, by_name, decode_custom
from common.quaternion import q_angle, q_conj, q_exp, q_mul
from gcs.session import GcsError, Session

M = MAV
MODE_NAMES = tuple(m.name for m in Mode)
_LANDED = {M.MAV_LANDED_STATE_ON_GROUND: "on ground", M.MAV_LANDED_STATE_IN_AIR: "in air",
           M.MAV_LANDED_STATE_TAKEOFF: "taking off", M.MAV_LANDED_STATE_LANDING: "landing",
           M.MAV_LANDED_STATE_UNDEFINED: "undefined"}


def mode_name(custom_mode: int, autopilot: int) -> str:
    """Our modes (PX4 encoding) by name; otherwise the raw custom mode."""
    if autopilot in (M.MAV_AUTOPILOT_GENERIC, M.MAV_AUTOPILOT_PX4):
        mode = decode_custom(custom_mode)
        if mode is not None:
            return mode.name
        main, sub = (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF
        return f"custom {main}.{sub}"
    return f"custom {custom_mode}"


@dataclass
class Snapshot:
    """The latest of each message type from the vehicle, and link statistics."""

    messages: dict[str, Any] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=dict)
    received: int = 0
    lost: int = 0
    started: float = field(default_factory=time.monotonic)
    texts: list[str] = field(default_factory=list)

    def update(self, msg) -> None:
        kind = msg.get_type()
        if kind == "BAD_DATA":
            return
        if kind == "STATUSTEXT":
            self.texts = [*self.texts[-9:], msg.text]
        self.messages[kind] = msg
        self.counts[kind] = self.counts.get(kind, 0) + 1

    def get(self, kind: str):
        return self.messages.get(kind)


def link_quality(session: Session) -> tuple[float, int, int]:
    """(loss percent, messages received, messages lost) from sequence numbers."""
    conn = session.conn
    return conn.packet_loss(), conn.mav_count, conn.mav_loss


def collect(session: Session, snapshot: Snapshot, seconds: float) -> Snapshot:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        msg = session.recv(None, timeout=max(0.01, deadline - time.monotonic()))
        if msg is not None and msg.get_srcSystem() == session.target_system:
            snapshot.update(msg)
    return snapshot


def status(session: Session, seconds: float = 1.5) -> dict[str, Any]:
    """Identity, mode, armed, position, attitude, health, as a dict."""
    session.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    snap = collect(session, Snapshot(), seconds)
    out: dict[str, Any] = {"system": session.target_system,
                           "component": session.target_component}
    hb = snap.get("HEARTBEAT")
    if hb is not None:
        out.update(type=M.enums["MAV_TYPE"][hb.type].name,
                   autopilot=M.enums["MAV_AUTOPILOT"][hb.autopilot].name,
                   mode=mode_name(hb.custom_mode, hb.autopilot),
                   armed=bool(hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED),
                   system_status=M.enums["MAV_STATE"][hb.system_status].name)
    av = snap.get("AUTOPILOT_VERSION")
    if av is not None:
        v = av.flight_sw_version
        out["version"] = f"{v >> 24}.{(v >> 16) & 0xFF}.{(v >> 8) & 0xFF}"
        out["capabilities"] = [e.name.replace("MAV_PROTOCOL_CAPABILITY_", "")
                               for bit, e in M.enums["MAV_PROTOCOL_CAPABILITY"].items()
                               if av.capabilities & bit and bit]
    pos = snap.get("LOCAL_POSITION_NED")
    if pos is not None:
        out["position_ned_m"] = [pos.x, pos.y, pos.z]
        out["velocity_ned_m_s"] = [pos.vx, pos.vy, pos.vz]
    att = snap.get("ATTITUDE_QUATERNION")
    if att is not None:
        out["q_ned_frd"] = [att.q1, att.q2, att.q3, att.q4]
    eul = snap.get("ATTITUDE")
    if eul is not None:
        out["roll_pitch_yaw_deg"] = [math.degrees(a) for a in (eul.roll, eul.pitch, eul.yaw)]
    gp = snap.get("GLOBAL_POSITION_INT")
    if gp is not None:
        out["global"] = {"lat_deg": gp.lat * 1e-7, "lon_deg": gp.lon * 1e-7,
                         "alt_m": gp.alt * 1e-3, "relative_alt_m": gp.relative_alt * 1e-3}
    ss = snap.get("SYS_STATUS")
    if ss is not None:
        present = ss.onboard_control_sensors_present
        health = ss.onboard_control_sensors_health
        out["health"] = "ok" if present & health == present else "unhealthy sensors: " + \
            ", ".join(e.name.replace("MAV_SYS_STATUS_SENSOR_", "") for bit, e in
                      M.enums["MAV_SYS_STATUS_SENSOR"].items()
                      if bit and present & bit and not health & bit)
        out["link_errors"] = ss.errors_comm
    ext = snap.get("EXTENDED_SYS_STATE")
    if ext is not None:
        out["landed"] = _LANDED.get(ext.landed_state, str(ext.landed_state))
    mc = snap.get("MISSION_CURRENT")
    if mc is not None:
        out["mission"] = {"current": mc.seq, "total": mc.total,
                          "state": M.enums["MISSION_STATE"][mc.mission_state].name
                          if mc.mission_state in M.enums["MISSION_STATE"] else mc.mission_state}
    loss, received, lost = link_quality(session)
    out["link"] = {"loss_percent": round(loss, 2), "received": received, "lost": lost}
    if snap.texts:
        out["messages"] = snap.texts
    return out


def vehicles(session: Session, seconds: float) -> list[int]:
    """System ids of the autopilots on the link: Zenoh liveliness tokens where the link has
    them (vehicles that left are gone), else heartbeats heard within `seconds`."""
    live = getattr(session.conn, "vehicles", None)
    if live is not None:
        time.sleep(min(seconds, 1.0))  # liveliness history arrives at once; let it settle
        return sorted(session.conn.vehicles)
    heard: set[int] = set()
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        msg = session.recv(["HEARTBEAT"], timeout=0.2)
        if msg is not None and msg.autopilot != M.MAV_AUTOPILOT_INVALID:
            heard.add(msg.get_srcSystem())
    return sorted(heard)


def set_mode(session: Session, name: str) -> int:
    mode = by_name(name)
    if mode is None:
        raise GcsError(f"unknown mode {name!r}: expected one of {', '.join(MODE_NAMES)}")
    main, sub = mode.value
    return session.command(M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                           main, sub)


def arm(session: Session, armed: bool, force: bool = False) -> int:
    return session.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0 if armed else 0.0,
                           21196.0 if force else 0.0)


# ------------------------------------------------------------------ parameters


def param_list(session: Session, timeout: float = 5.0) -> dict[str, float]:
    """All parameters (PARAM_REQUEST_LIST), re-reading missing indices once."""
    s = session
    s.send(M.MAVLink_param_request_list_message(s.target_system, s.target_component))
    values: dict[int, tuple[str, float]] = {}
    count = None
    deadline = time.monotonic() + timeout
    quiet_until = time.monotonic() + 1.0
    while time.monotonic() < deadline:
        msg = s.recv(["PARAM_VALUE"], timeout=0.2)
        if msg is None:
            if count is not None and time.monotonic() > quiet_until:
                missing = [i for i in range(count) if i not in values]
                if not missing:
                    break
                for i in missing:  # the spec's recovery: request what did not arrive
                    s.send(M.MAVLink_param_request_read_message(
                        s.target_system, s.target_component, b"", i))
                quiet_until = time.monotonic() + 1.0
            continue
        count = msg.param_count
        values[msg.param_index] = (msg.param_id, msg.param_value)
        quiet_until = time.monotonic() + 0.3
        if len(values) == count:
            break
    if count is None:
        raise GcsError("no PARAM_VALUE answered PARAM_REQUEST_LIST")
    if len(values) != count:
        raise GcsError(f"received {len(values)} of {count} parameters")
    return {name: value for _, (name, value) in sorted(values.items())}


def param_get(session: Session, name: str, timeout: float = 2.0) -> float:
    s = session
    for _ in range(3):
        s.send(M.MAVLink_param_request_read_message(s.target_system, s.target_component,
                                                    name.encode(), -1))
        deadline = time.monotonic() + timeout / 3
        while time.monotonic() < deadline:
            msg = s.recv(["PARAM_VALUE"], timeout=0.1)
            if msg is not None and msg.param_id == name:
                return msg.param_value
    raise GcsError(f"parameter {name} not answered (unknown to the vehicle?)")


def param_set(session: Session, name: str, value: float, timeout: float = 2.0
              ) -> tuple[float, list[str]]:
    """Set a parameter; returns (value now in force, STATUSTEXTs heard meanwhile)."""
    s = session
    texts: list[str] = []
    for _ in range(3):
        s.send(M.MAVLink_param_set_message(s.target_system, s.target_component, name.encode(),
                                           value, M.MAV_PARAM_TYPE_REAL32))
        deadline = time.monotonic() + timeout / 3
        while time.monotonic() < deadline:
            msg = s.recv(["PARAM_VALUE", "STATUSTEXT"], timeout=0.1)
            if msg is None:
                continue
            if msg.get_type() == "STATUSTEXT":
                texts.append(msg.text)
            elif msg.param_id == name:
                # a refusal may come just before or after the echo
                texts += [m.text for m in iter(lambda: s.recv(["STATUSTEXT"], timeout=0.2),
                                               None)]
                return msg.param_value, texts
    raise GcsError(f"parameter {name} not answered")


# ------------------------------------------------------------------ offboard pose


@dataclass(frozen=True)
class PoseTarget:
    """A 6-DoF pose in local NED: position and attitude q_ned_frd."""

    p_ned_m: tuple[float, float, float]
    q_ned_frd: tuple[float, float, float, float]

    @classmethod
    def from_euler_deg(cls, p_ned_m, roll: float, pitch: float, yaw: float) -> PoseTarget:
        """Z-Y-X (yaw, pitch, roll) in NED/FRD, as ground stations show attitudes."""
        q = q_mul(q_exp((0.0, 0.0, math.radians(yaw))),
                  q_mul(q_exp((0.0, math.radians(pitch), 0.0)),
                        q_exp((math.radians(roll), 0.0, 0.0))))
        return cls(tuple(p_ned_m), q)

    def messages(self, session: Session) -> list:
        s = session
        pos = M.MAVLink_set_position_target_local_ned_message(
            0, s.target_system, s.target_component, M.MAV_FRAME_LOCAL_NED,
            0b0000_1101_1111_1000, *self.p_ned_m, 0, 0, 0, 0, 0, 0, 0, 0)
        att = M.MAVLink_set_attitude_target_message(
            0, s.target_system, s.target_component, 0b0100_0111, list(self.q_ned_frd), 0, 0, 0,
            0)
        return [pos, att]


def pose_errors(snap: Snapshot, target: PoseTarget) -> tuple[float, float] | None:
    pos, att = snap.get("LOCAL_POSITION_NED"), snap.get("ATTITUDE_QUATERNION")
    if pos is None or att is None:
        return None
    dp = math.dist((pos.x, pos.y, pos.z), target.p_ned_m)
    q = (att.q1, att.q2, att.q3, att.q4)
    return dp, q_angle(q_mul(q_conj(target.q_ned_frd), q))


def goto(session: Session, target: PoseTarget, *, arm_first: bool, tolerance_m: float,
         tolerance_rad: float, timeout: float, hold_s: float, rate_hz: float = 20.0,
         report=None) -> tuple[float, float]:
    """Stream the pose target, switch to OFFBOARD (arming if asked), wait until reached."""
    s = session
    period = 1.0 / rate_hz
    snap = Snapshot()

    def stream(seconds: float, until=None):
        end = time.monotonic() + seconds
        next_send = 0.0
        while time.monotonic() < end:
            now = time.monotonic()
            if now >= next_send:
                for msg in target.messages(s):
                    s.send(msg)
                next_send = now + period
            msg = s.recv(None, timeout=min(period, max(0.0, end - now)))
            if msg is not None and msg.get_srcSystem() == s.target_system:
                snap.update(msg)
            if until is not None and until():
                return True
        return False

    stream(0.5)  # PX4 and this FCU need a setpoint stream before OFFBOARD is accepted
    # a vehicle arms only once it knows its state: wait for its position to be reported
    stream(10.0, until=lambda: snap.get("LOCAL_POSITION_NED") is not None)
    if arm_first and arm(s, True) != M.MAV_RESULT_ACCEPTED:
        raise GcsError("arming refused")
    result = set_mode(s, "OFFBOARD")
    if result != M.MAV_RESULT_ACCEPTED:
        raise GcsError(f"OFFBOARD refused (MAV_RESULT {result})")

    def reached() -> bool:
        errs = pose_errors(snap, target)
        if report is not None and errs is not None:
            report(errs)
        return errs is not None and errs[0] <= tolerance_m and errs[1] <= tolerance_rad

    if not stream(timeout, reached):
        errs = pose_errors(snap, target)
        raise GcsError(f"pose not reached within {timeout:.0f} s (errors {errs})")
    stream(hold_s)
    return pose_errors(snap, target)  # type: ignore[return-value]
