"""`gcs status` and `gcs vehicles`: the vehicle's identity, mode, state and health as a
dict and as lines for people; the names of modes and landed states; the vehicles on a
link."""

from __future__ import annotations

import math
import time
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from common.wire.mavlink import MAV
from common.wire.rounding import f32
from gcs.autopilot import autopilot_of
from gcs.autopilot.health import format_readiness as _format_readiness
from gcs.autopilot.health import health as _health
from gcs.autopilot.health import readiness as _readiness
from gcs.vehicle_link.session import Session
from gcs.vehicle_link.snapshot import Snapshot, collect_requested, link_quality

M = MAV
NO_MISSION = 65535  # MISSION_CURRENT.total: no mission uploaded
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


def heartbeat_mode(heartbeat: Any) -> str:
    """The mode a HEARTBEAT shows, in its autopilot's own spelling."""
    return autopilot_of(heartbeat).mode_name(heartbeat.custom_mode)


def landed_name(state: int) -> str:
    """EXTENDED_SYS_STATE.landed_state in words."""
    return _LANDED.get(state, f"landed state {state}")



# What `status` asks for (MAV_CMD_REQUEST_MESSAGE) rather than waiting for a stream to bring
# it: the identity, and the landed state and mission that vehicles send at 1 Hz or less.
STATUS_REQUESTS = {"AUTOPILOT_VERSION": M.MAVLINK_MSG_ID_AUTOPILOT_VERSION,
                   "EXTENDED_SYS_STATE": M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
                   "MISSION_CURRENT": M.MAVLINK_MSG_ID_MISSION_CURRENT}



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
        out["position_ned_m"] = [_shortest_f32(pos.x), _shortest_f32(pos.y), _shortest_f32(pos.z)]
        out["velocity_ned_m_s"] = [_shortest_f32(pos.vx), _shortest_f32(pos.vy),
                                   _shortest_f32(pos.vz)]
    att = snap.get("ATTITUDE_QUATERNION")
    if att is not None:
        out["q_ned_frd"] = [_shortest_f32(q) for q in (att.q1, att.q2, att.q3, att.q4)]
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
        px4 = hb is not None and hb.autopilot == M.MAV_AUTOPILOT_PX4
        out["readiness"] = _readiness(ss, snap.get("EKF_STATUS_REPORT"), snap.texts,
                                      prearm_in_health=px4)
    ext = snap.get("EXTENDED_SYS_STATE")
    if ext is not None:
        out["landed"] = landed_name(ext.landed_state)
    mc = snap.get("MISSION_CURRENT")
    if mc is not None:
        # total UINT16_MAX: no mission on the vehicle (MAVLink's MISSION_CURRENT), as 0
        out["mission"] = {"current": mc.seq, "total": 0 if mc.total == NO_MISSION else mc.total,
                          "state": M.enums["MISSION_STATE"][mc.mission_state].name
                          if mc.mission_state in M.enums["MISSION_STATE"] else mc.mission_state}
    loss, received, lost = link_quality(session)
    out["link"] = {"loss_percent": round(loss, 2), "received": received, "lost": lost}
    if snap.texts:
        out["messages"] = snap.texts
    return out


def _shortest_f32(value: float) -> float | None:
    """A float32 field as the shortest decimal that is the same float32 (0.1, not
    0.10000000149011612); None for a value JSON cannot carry."""
    if not math.isfinite(value):
        return None
    for digits in range(1, 10):
        short = float(f"{value:.{digits}g}")
        if f32(short) == value:
            return short + 0.0  # no -0.0
    return value


def _round(value: float, digits: int) -> float | None:
    return round(value, digits) + 0.0 if math.isfinite(value) else None


def _numbers(values: Iterable[float | None], fmt: str) -> str:
    return ", ".join("nan" if v is None else format(v + 0.0, fmt) for v in values)


def format_status(status: dict[str, Any]) -> list[str]:
    """`status()` for people: one `key: value` line each, values with units and sensible
    digits (millimetres, hundredths of a degree), no Python notation."""
    units = {"position_ned_m": (".3f", "m"), "velocity_ned_m_s": (".3f", "m/s"),
             "q_ned_frd": (".4f", ""), "roll_pitch_yaw_deg": (".2f", "deg")}
    lines: list[str] = []
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
