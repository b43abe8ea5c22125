"""Ground-station actions on a connected vehicle, in standard MAVLink only, so that they work
against PX4 and ArduPilot for the standard parts: status, arming, modes, parameters,
offboard pose setpoints, recording. What differs between autopilots (mode names and
encodings, takeoff, which set-points a pose goto streams, health and readiness) comes from
`gcs.autopilot`, chosen by the vehicle's HEARTBEAT.
"""

from __future__ import annotations

import math
import struct
import threading
import time
import weakref
from dataclasses import dataclass, field
from typing import Any

from common.mavlink import MAV
from common.outcome import ATTITUDE_NOT_FLOWN
from common.quaternion import q_angle, q_conj, q_exp, q_mul
from gcs import param_wire
from gcs.autopilot import ARDUPILOT, Autopilot, ModeTarget, autopilot_of
from gcs.autopilot import commands as _commands
from gcs.autopilot.health import format_readiness as _format_readiness
from gcs.autopilot.health import health as _health
from gcs.autopilot.health import readiness as _readiness
from gcs.session import GcsError, Session

M = MAV
_LANDED = {M.MAV_LANDED_STATE_ON_GROUND: "on ground", M.MAV_LANDED_STATE_IN_AIR: "in air",
           M.MAV_LANDED_STATE_TAKEOFF: "taking off", M.MAV_LANDED_STATE_LANDING: "landing",
           M.MAV_LANDED_STATE_UNDEFINED: "undefined"}


def mode_name(custom_mode: int, autopilot: int, mav_type: int | None = None) -> str:
    """A custom mode in its autopilot's own spelling (`gcs.autopilot`): PX4's (also under
    MAV_AUTOPILOT_GENERIC, as this FCU said before), ArduPilot's by vehicle type (pymavlink's
    names); the raw custom mode where it cannot be named."""
    if autopilot == M.MAV_AUTOPILOT_ARDUPILOTMEGA and mav_type is None:
        return f"custom {custom_mode}"
    return heartbeat_mode(_Beat(autopilot, mav_type or 0, custom_mode))


@dataclass(frozen=True)
class _Beat:
    autopilot: int
    type: int
    custom_mode: int


def heartbeat_mode(heartbeat) -> str:
    """The mode a HEARTBEAT shows, in its autopilot's own spelling."""
    return autopilot_of(heartbeat).mode_name(heartbeat.custom_mode)


def landed_name(state: int) -> str:
    """EXTENDED_SYS_STATE.landed_state in words."""
    return _LANDED.get(state, f"landed state {state}")


@dataclass
class Snapshot:
    """The latest of each message type from the vehicle, when each was heard (monotonic
    seconds), the last status texts (and the last failsafe text: severity CRITICAL or
    worse), and link statistics."""

    messages: dict[str, Any] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=dict)
    heard: dict[str, float] = field(default_factory=dict)
    received: int = 0
    lost: int = 0
    started: float = field(default_factory=time.monotonic)
    texts: list[str] = field(default_factory=list)
    failsafe_text: str = ""
    rate_samples: list[tuple[float, int]] = field(default_factory=list)  # (when, received)

    def update(self, msg, now: float | None = None) -> None:
        kind = msg.get_type()
        if kind == "BAD_DATA":
            return
        if kind == "STATUSTEXT":
            self.texts = [*self.texts[-9:], msg.text]
            if msg.severity <= M.MAV_SEVERITY_CRITICAL:
                self.failsafe_text = msg.text
        self.messages[kind] = msg
        self.counts[kind] = self.counts.get(kind, 0) + 1
        self.heard[kind] = time.monotonic() if now is None else now

    def get(self, kind: str):
        return self.messages.get(kind)

    def age(self, kind: str, now: float) -> float | None:
        """Seconds since the last message of this type, None if never heard."""
        t = self.heard.get(kind)
        return None if t is None else now - t


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


# What `status` asks for (MAV_CMD_REQUEST_MESSAGE) rather than waiting for a stream to bring
# it: the identity, and the landed state and mission that vehicles send at 1 Hz or less.
STATUS_REQUESTS = {"AUTOPILOT_VERSION": M.MAVLINK_MSG_ID_AUTOPILOT_VERSION,
                   "EXTENDED_SYS_STATE": M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
                   "MISSION_CURRENT": M.MAVLINK_MSG_ID_MISSION_CURRENT}


def collect_requested(session: Session, snapshot: Snapshot, requests: dict[str, int],
                      seconds: float, patience: float) -> Snapshot:
    """Listen for `seconds`, and on until each requested message has come (asked again
    every second) or its request was refused, at most `patience` seconds longer. The
    requests go out together and their answers are read with everything else: waiting for
    one request's COMMAND_ACK would drop the message another one brought."""
    s = session
    start = time.monotonic()
    wanted = dict(requests)
    asked_at = -math.inf
    while True:
        now = time.monotonic()
        missing = {name: i for name, i in wanted.items() if snapshot.get(name) is None}
        if (now - start >= seconds and not missing) or now - start >= seconds + patience:
            return snapshot
        if missing and now - asked_at >= 1.0:
            for msg_id in missing.values():
                s.send(M.MAVLink_command_long_message(s.target_system, s.target_component,
                                                      M.MAV_CMD_REQUEST_MESSAGE, 0, msg_id,
                                                      0, 0, 0, 0, 0, 0))
            asked_at = now
        msg = s.recv(None, timeout=0.05)
        if msg is None or msg.get_srcSystem() != s.target_system:
            continue
        snapshot.update(msg)
        if msg.get_type() == "COMMAND_ACK" and msg.command == M.MAV_CMD_REQUEST_MESSAGE and \
                msg.result not in (M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_IN_PROGRESS):
            wanted = {}  # an ACK does not say which request it answers: stop asking


def status(session: Session, seconds: float = 1.5, patience: float = 3.0) -> dict[str, Any]:
    """Identity, mode, armed, position, attitude, health, as a dict: what the vehicle sent
    in `seconds`, and what STATUS_REQUESTS asks for, waited for up to `patience` more."""
    snap = collect_requested(session, Snapshot(), STATUS_REQUESTS, seconds, patience)
    out: dict[str, Any] = {"system": session.target_system,
                           "component": session.target_component}
    hb = snap.get("HEARTBEAT")
    if hb is not None:
        out.update(type=M.enums["MAV_TYPE"][hb.type].name,
                   autopilot=M.enums["MAV_AUTOPILOT"][hb.autopilot].name,
                   mode=heartbeat_mode(hb),
                   armed=bool(hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED),
                   system_status=M.enums["MAV_STATE"][hb.system_status].name)
    av = snap.get("AUTOPILOT_VERSION")
    if av is not None:
        v = av.flight_sw_version
        out["version"] = f"{v >> 24}.{(v >> 16) & 0xFF}.{(v >> 8) & 0xFF}"
        out["capabilities"] = [e.name.replace("MAV_PROTOCOL_CAPABILITY_", "")
                               for bit, e in M.enums["MAV_PROTOCOL_CAPABILITY"].items()
                               if av.capabilities & bit and bit & (bit - 1) == 0
                               and not e.name.endswith("ENUM_END")]
    pos = snap.get("LOCAL_POSITION_NED")
    if pos is not None:
        out["position_ned_m"] = [_f32(pos.x), _f32(pos.y), _f32(pos.z)]
        out["velocity_ned_m_s"] = [_f32(pos.vx), _f32(pos.vy), _f32(pos.vz)]
    att = snap.get("ATTITUDE_QUATERNION")
    if att is not None:
        out["q_ned_frd"] = [_f32(q) for q in (att.q1, att.q2, att.q3, att.q4)]
    eul = snap.get("ATTITUDE")
    if eul is not None:
        out["roll_pitch_yaw_deg"] = [_round(math.degrees(a), 3)
                                     for a in (eul.roll, eul.pitch, eul.yaw)]
    gp = snap.get("GLOBAL_POSITION_INT")
    if gp is not None:
        out["global"] = {"lat_deg": round(gp.lat * 1e-7, 7), "lon_deg": round(gp.lon * 1e-7, 7),
                         "alt_m": round(gp.alt * 1e-3, 3),
                         "relative_alt_m": round(gp.relative_alt * 1e-3, 3)}
    ss = snap.get("SYS_STATUS")
    if ss is not None:
        out["health"] = _health(ss)
        out["link_errors"] = ss.errors_comm
    if ss is not None or snap.get("EKF_STATUS_REPORT") is not None:
        out["readiness"] = _readiness(ss, snap.get("EKF_STATUS_REPORT"), snap.texts)
    ext = snap.get("EXTENDED_SYS_STATE")
    if ext is not None:
        out["landed"] = landed_name(ext.landed_state)
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


def _f32(value: float) -> float | None:
    """A float32 field as the shortest decimal that is the same float32 (0.1, not
    0.10000000149011612); None for a value JSON cannot carry."""
    if not math.isfinite(value):
        return None
    for digits in range(1, 10):
        short = float(f"{value:.{digits}g}")
        if struct.unpack("<f", struct.pack("<f", short))[0] == value:
            return short + 0.0  # no -0.0
    return value


def _round(value: float, digits: int) -> float | None:
    return round(value, digits) + 0.0 if math.isfinite(value) else None


def _numbers(values, fmt: str) -> str:
    return ", ".join("nan" if v is None else format(v + 0.0, fmt) for v in values)


def format_status(status: dict[str, Any]) -> list[str]:
    """`status()` for people: one `key: value` line each, values with units and sensible
    digits (millimetres, hundredths of a degree), no Python notation."""
    units = {"position_ned_m": (".3f", "m"), "velocity_ned_m_s": (".3f", "m/s"),
             "q_ned_frd": (".4f", ""), "roll_pitch_yaw_deg": (".2f", "deg")}
    lines = []
    for key, value in status.items():
        if key == "system":
            text = f"{value} (component {status.get('component', '?')})"
        elif key == "component":
            continue
        elif key == "armed":
            text = "yes" if value else "no"
        elif key in units:
            fmt, unit = units[key]
            text = _numbers(value, fmt) + (f" {unit}" if unit else "")
        elif key == "global":
            text = (f"lat {value['lat_deg']:.7f}, lon {value['lon_deg']:.7f} deg, "
                    f"alt {value['alt_m']:.2f} m (relative {value['relative_alt_m']:.2f} m)")
        elif key == "mission":
            text = (f"item {value['current']} of {value['total']}, {value['state']}"
                    if value["total"] else f"none, {value['state']}")
        elif key == "link":
            text = (f"{value['loss_percent']:.2f} % lost ({value['lost']} of "
                    f"{value['received'] + value['lost']} messages)")
        elif key == "capabilities":
            text = ", ".join(value)
        elif key == "readiness":
            text = _format_readiness(value)
        elif key == "messages":
            lines += [f"{'message':>18}: {t}" for t in value]
            continue
        else:
            text = str(value)
        lines.append(f"{key:>18}: {text}")
    return lines


def vehicles(session: Session, seconds: float) -> list[int]:
    """System ids of the autopilots on the link: Zenoh liveliness tokens where the link has
    them (vehicles that left are gone), else heartbeats heard within `seconds`."""
    live = getattr(session.conn, "vehicles", None)
    if live is not None:
        time.sleep(min(seconds, 1.0))  # liveliness history arrives at once; let it settle
        return sorted(session.conn.vehicles or ())
    heard: set[int] = set()
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        msg = session.recv(["HEARTBEAT"], timeout=0.2)
        if msg is not None and msg.autopilot != M.MAV_AUTOPILOT_INVALID:
            heard.add(msg.get_srcSystem())
    return sorted(heard)


def _autopilot(session: Session) -> Autopilot:
    return _commands.autopilot(session)


def set_mode(session: Session, name: str, confirm_s: float = _commands.CONFIRM_S) -> int:
    """Change mode by name: the vehicle's own names or the portable ones (`gcs.autopilot`;
    UnknownMode for a name it lacks); TAKEOFF is the takeoff procedure at its default height.
    The vehicle's answer; ACCEPTED only once a HEARTBEAT showed the mode, else GcsError
    "not confirmed: the vehicle is in X"."""
    target = _autopilot(session).resolve_mode(name)
    try:
        if target.takeoff:
            try:
                return takeoff(session, _commands.DEFAULT_TAKEOFF_M, confirm_s=confirm_s)[0]
            except GcsError as exc:
                raise GcsError(f"takeoff: {exc}") from None
        return _commands.set_mode(session, target, confirm_s)
    except _commands.NotConfirmed as exc:
        raise GcsError(str(exc)) from None


def takeoff(session: Session, height_m: float, *, reach_s: float | None = None,
            tolerance_m: float = 0.5, confirm_s: float = _commands.CONFIRM_S,
            report=None) -> tuple[int, float | None]:
    """Take off to `height_m` above home, the autopilot's way (`gcs.autopilot.commands`);
    (the vehicle's answer, the height reached when waited for `reach_s`). GcsError for a
    vehicle disarmed or in the air, or one that does not climb."""
    try:
        return _commands.takeoff(session, height_m, reach_s=reach_s, tolerance_m=tolerance_m,
                                 confirm_s=confirm_s, report=report, fail=GcsError)
    except _commands.NotConfirmed as exc:
        raise GcsError(str(exc)) from None


def arm(session: Session, armed: bool, force: bool = False) -> int:
    return session.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0 if armed else 0.0,
                           21196.0 if force else 0.0)


# ------------------------------------------------------------------ parameters


@dataclass(frozen=True)
class ParamValue:
    """A parameter's value (an integer for the integer types) and its MAV_PARAM_TYPE."""

    value: float
    param_type: int = M.MAV_PARAM_TYPE_REAL32

    @property
    def is_integer(self) -> bool:
        return self.param_type not in param_wire.FLOAT_TYPES

    def text(self) -> str:
        """As `gcs param` prints it: an integer type as an integer, a float with :g."""
        return str(int(self.value)) if self.is_integer else f"{self.value:g}"


_ENCODINGS: weakref.WeakKeyDictionary[Session, str] = weakref.WeakKeyDictionary()
ECHO_QUIET_S = 0.2  # after a set's echo, how long to listen for a later echo or a reason


def autopilot_version(session: Session, timeout: float = 0.5):
    """The vehicle's AUTOPILOT_VERSION: the last one heard, else asked for once
    (REQUEST_MESSAGE); None when it sends none."""
    s = session
    ver = s.conn.messages.get("AUTOPILOT_VERSION")
    if ver is None:
        try:
            s.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION,
                      timeout=timeout, retries=1)
            ver = s.conn.messages.get("AUTOPILOT_VERSION") or \
                s.recv(["AUTOPILOT_VERSION"], timeout=timeout)
        except GcsError:
            ver = None
    return ver if ver is not None and ver.get_srcSystem() == s.target_system else None


def param_encoding(session: Session) -> str:
    """How the vehicle carries integer parameters (`gcs.param_wire`): its AUTOPILOT_VERSION
    capabilities, else by autopilot (ArduPilot casts, PX4 sends bytes); asked once per
    session."""
    known = _ENCODINGS.get(session)
    if known is None:
        ver = autopilot_version(session)
        hb = session.heartbeat_msg
        ardupilot = hb is not None and autopilot_of(hb).kind == ARDUPILOT
        known = param_wire.encoding_of(None if ver is None else ver.capabilities, ardupilot)
        _ENCODINGS[session] = known
    return known


def _decoded(session: Session, raw: bytes, param_type: int) -> ParamValue:
    """A PARAM_VALUE's four bytes as the value of its type (asks for the encoding only
    for an integer type: float parameters read the same either way)."""
    encoding = param_wire.C_CAST if param_type in param_wire.FLOAT_TYPES else \
        param_encoding(session)
    return ParamValue(param_wire.decode(raw, param_type, encoding), param_type)


def param_values(session: Session, timeout: float = 5.0) -> dict[str, ParamValue]:
    """All parameters with their types (PARAM_REQUEST_LIST), re-reading missing indices
    once; `timeout` without a new parameter ends it."""
    s = session
    s.send(M.MAVLink_param_request_list_message(s.target_system, s.target_component))
    values: dict[int, tuple[str, bytes, int]] = {}
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
        if msg.get_srcSystem() != s.target_system:
            continue
        count = msg.param_count
        if msg.param_index not in values:
            deadline = max(deadline, time.monotonic() + timeout)
        values[msg.param_index] = (msg.param_id, param_wire.raw_value(msg), msg.param_type)
        quiet_until = time.monotonic() + 0.3
        if len(values) == count:
            break
    if count is None:
        raise GcsError("no PARAM_VALUE answered PARAM_REQUEST_LIST")
    if len(values) != count:
        raise GcsError(f"received {len(values)} of {count} parameters")
    return {name: _decoded(s, raw, ptype) for _, (name, raw, ptype) in sorted(values.items())}


def param_list(session: Session, timeout: float = 5.0) -> dict[str, float]:
    """All parameters' values (`param_values` without the types)."""
    return {name: p.value for name, p in param_values(session, timeout).items()}


def param_read(session: Session, name: str, timeout: float = 2.0) -> ParamValue:
    """One parameter with its type (PARAM_REQUEST_READ by name, three tries)."""
    s = session
    for _ in range(3):
        s.send(M.MAVLink_param_request_read_message(s.target_system, s.target_component,
                                                    name.encode(), -1))
        deadline = time.monotonic() + timeout / 3
        while time.monotonic() < deadline:
            msg = s.recv(["PARAM_VALUE"], timeout=0.1)
            if msg is not None and msg.param_id == name and \
                    msg.get_srcSystem() == s.target_system:
                return _decoded(s, param_wire.raw_value(msg), msg.param_type)
    raise GcsError(f"parameter {name} not answered (unknown to the vehicle?)")


def param_get(session: Session, name: str, timeout: float = 2.0) -> float:
    return param_read(session, name, timeout).value


def param_set(session: Session, name: str, value: float, timeout: float = 2.0, *,
              param_type: int | None = None) -> tuple[float, list[str]]:
    """Set a parameter in its real type (read first unless `param_type` is given), encoded
    as the vehicle carries it; returns (value now in force, STATUSTEXTs heard meanwhile).
    The value in force is the echo that equals what was sent if one came within
    ECHO_QUIET_S of the first (a stale answer to the read may come first), else the last
    echo: a vehicle that clamps the value echoes the clamped one. ParamValueError for a
    value the type cannot carry."""
    s = session
    if param_type is None:
        param_type = param_read(s, name, timeout).param_type
    encoding = param_wire.C_CAST if param_type in param_wire.FLOAT_TYPES else \
        param_encoding(s)
    raw = param_wire.encode(name, value, param_type, encoding)
    want = param_wire.intended(name, value, param_type)
    texts: list[str] = []
    echoes: list[float] = []
    for _ in range(3):
        s.send(param_wire.param_set_message(s.target_system, s.target_component, name, raw,
                                            param_type))
        deadline = time.monotonic() + timeout / 3
        while (left := deadline - time.monotonic()) > 0.0:
            msg = s.recv(["PARAM_VALUE", "STATUSTEXT"], timeout=min(0.1, left))
            if msg is None or msg.get_srcSystem() != s.target_system:
                continue
            if msg.get_type() == "STATUSTEXT":
                texts.append(msg.text)
            elif msg.param_id == name:
                echoes.append(param_wire.decode(param_wire.raw_value(msg), param_type,
                                                encoding))
                deadline = time.monotonic() + ECHO_QUIET_S  # a refusal may come just after
        if echoes:
            return (want if want in echoes else echoes[-1]), texts
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

    @property
    def yaw_rad(self) -> float:
        """The attitude's Z-Y-X yaw (NED, rad)."""
        return _yaw_rad(self.q_ned_frd)

    def messages(self, session: Session, attitude: bool = True) -> list:
        """The set-points: the position (yaw ignored) and the attitude target; or, without
        `attitude` (ArduPilot's GUIDED, where an attitude target replaces the position
        target), the position with the yaw alone."""
        s = session
        if not attitude:
            return [M.MAVLink_set_position_target_local_ned_message(
                0, s.target_system, s.target_component, M.MAV_FRAME_LOCAL_NED,
                POSITION_AND_YAW, *self.p_ned_m, 0, 0, 0, 0, 0, 0, self.yaw_rad, 0)]
        pos = M.MAVLink_set_position_target_local_ned_message(
            0, s.target_system, s.target_component, M.MAV_FRAME_LOCAL_NED,
            POSITION_ONLY, *self.p_ned_m, 0, 0, 0, 0, 0, 0, 0, 0)
        att = M.MAVLink_set_attitude_target_message(
            0, s.target_system, s.target_component, 0b0100_0111, list(self.q_ned_frd), 0, 0, 0,
            0)
        return [pos, att]


# SET_POSITION_TARGET_LOCAL_NED type_mask: bits set are ignored (velocity 3-5, acceleration
# 6-8, yaw 10, yaw rate 11)
POSITION_ONLY = 0b0000_1101_1111_1000
POSITION_AND_YAW = 0b0000_1001_1111_1000


def _yaw_rad(q: tuple[float, float, float, float]) -> float:
    w, x, y, z = q
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def pose_errors(snap: Snapshot, target: PoseTarget, attitude: bool = True
                ) -> tuple[float, float] | None:
    """(position error m, attitude error rad); without `attitude`, the yaw error alone."""
    pos, att = snap.get("LOCAL_POSITION_NED"), snap.get("ATTITUDE_QUATERNION")
    if pos is None or att is None:
        return None
    dp = math.dist((pos.x, pos.y, pos.z), target.p_ned_m)
    q = (att.q1, att.q2, att.q3, att.q4)
    if not attitude:
        dyaw = _yaw_rad(q) - target.yaw_rad
        return dp, abs(math.atan2(math.sin(dyaw), math.cos(dyaw)))
    return dp, q_angle(q_mul(q_conj(target.q_ned_frd), q))


class SetpointStream:
    """Sends a pose target's two messages at `rate_hz` from its own thread until stopped,
    whatever the caller waits for meanwhile (a command's answer, say), as MAVSDK's offboard
    plugin does: PX4 and this FCU leave OFFBOARD once the stream pauses for COM_OF_LOSS_T."""

    def __init__(self, session: Session, target: PoseTarget, rate_hz: float,
                 attitude: bool = True) -> None:
        self._messages = target.messages(session, attitude)
        self._session = session
        self._period = 1.0 / rate_hz
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="gcs-setpoints", daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            for msg in self._messages:
                self._session.send(msg)
            self._stop.wait(self._period)

    def start(self) -> None:
        """Start sending (once; later calls do nothing)."""
        if not self._thread.is_alive() and not self._stop.is_set():
            self._thread.start()

    def __enter__(self) -> SetpointStream:
        """The stream, not yet sending: `start` it (gcs goto starts it when the mode needs
        it)."""
        return self

    def __exit__(self, *_exc: object) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)


def goto(session: Session, target: PoseTarget, *, arm_first: bool, tolerance_m: float,
         tolerance_rad: float, timeout: float, hold_s: float, rate_hz: float = 20.0,
         report=None) -> tuple[float, float]:
    """Fly to the pose in the autopilot's set-point mode (`Autopilot.guided_mode`), arming
    if asked, and wait until reached and held for `hold_s`. PX4 and this FCU: stream the
    position and attitude targets, then OFFBOARD (it needs the stream first). ArduPilot:
    GUIDED, then the position and yaw alone (an attitude target would replace the
    position target); the attitude error is then the yaw's. GcsError when refused, not
    confirmed, not reached within `timeout`, when the vehicle leaves the mode meanwhile
    (a failsafe, another ground station), or when it says it holds its attitude instead
    of the target's (this FCU: a tilt would flip), with its reason."""
    s = session
    ap = _autopilot(s)
    full = ap.attitude_targets
    mode = ap.resolve_mode(ap.guided_mode)
    snap = Snapshot()
    accepted_at = math.inf  # when the mode was confirmed (monotonic s)

    def listen(seconds: float, until=None) -> bool:
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0.0:
            msg = s.recv(None, timeout=min(0.05, left))
            if msg is not None and msg.get_srcSystem() == s.target_system:
                snap.update(msg)
                if msg.get_type() == "STATUSTEXT" and time.monotonic() > accepted_at and \
                        str(msg.text).startswith(ATTITUDE_NOT_FLOWN):
                    raise GcsError(f"the vehicle does not fly this attitude: {msg.text}")
            hb = snap.get("HEARTBEAT")
            if hb is not None and snap.heard["HEARTBEAT"] > accepted_at and \
                    not ap.same_mode(mode.custom_mode, hb.custom_mode):
                why = f" ({snap.failsafe_text})" if snap.failsafe_text else ""
                raise GcsError(f"the vehicle left {mode.name}: now "
                               f"{ap.mode_name(hb.custom_mode)}{why}")
            if until is not None and until():
                return True
        return False

    with SetpointStream(s, target, rate_hz, attitude=full) as stream:
        if full:
            stream.start()
            listen(0.5)  # PX4 and this FCU need a setpoint stream before OFFBOARD is accepted
        # a vehicle arms only once it knows its state: wait for its position to be reported
        listen(10.0, until=lambda: snap.get("LOCAL_POSITION_NED") is not None)
        if arm_first and (result := arm(s, True)) != M.MAV_RESULT_ACCEPTED:
            raise GcsError(f"arming refused: {s.describe(result)}")
        _set_mode_or_fail(s, mode)
        stream.start()  # ArduPilot: the targets count only once in GUIDED
        accepted_at = time.monotonic()
        snap.failsafe_text = ""  # a failsafe from before does not explain what follows

        def reached() -> bool:
            errs = pose_errors(snap, target, full)
            if report is not None and errs is not None:
                report(errs)
            return errs is not None and errs[0] <= tolerance_m and errs[1] <= tolerance_rad

        if not listen(timeout, reached):
            errs = pose_errors(snap, target, full)
            what = "attitude" if full else "yaw"
            where = "no position heard" if errs is None else \
                f"position error {errs[0]:.3f} m, {what} error {math.degrees(errs[1]):.2f} deg"
            raise GcsError(f"pose not reached within {timeout:g} s ({where})")
        listen(hold_s)
        return pose_errors(snap, target, full)  # type: ignore[return-value]


def _set_mode_or_fail(session: Session, mode: ModeTarget) -> None:
    """The mode, confirmed by a HEARTBEAT; GcsError with the vehicle's reason otherwise."""
    try:
        result = _commands.set_mode(session, mode)
    except _commands.NotConfirmed as exc:
        raise GcsError(f"{mode.name} {exc}") from None
    if result != M.MAV_RESULT_ACCEPTED:
        raise GcsError(f"{mode.name} refused: {session.describe(result)}")
