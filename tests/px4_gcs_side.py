"""A scripted PX4 as a ground station meets it (MAVLink over loopback UDP), written from
PX4's own handling, so that `gcs goto`, `takeoff` and `mode` are tested against what PX4
does with their messages, not against this project's FCU:

- OFFBOARD is accepted only while set-points arrive (COM_OF_LOSS_T, 1 s; commander's
  offboard check), and left for AUTO.LOITER when they stop;
- SET_POSITION_TARGET_LOCAL_NED flies the position (and the yaw, where not ignored);
  SET_ATTITUDE_TARGET turns offboard control into attitude control with position control
  off, its thrust as given, zero with the "ignore throttle" bit (mavlink_receiver.cpp,
  handle_message_set_attitude_target): a vehicle so driven in a hover falls;
- MAV_CMD_NAV_TAKEOFF (p7 AMSL) climbs in AUTO.TAKEOFF and then holds in AUTO.LOITER;
  AUTO.LAND descends at MPC_LAND_SPEED and disarms on the ground; AUTO.RTL returns home
  and lands; the descent limit is MPC_Z_VEL_MAX_DN;
- AUTOPILOT_VERSION carries a git hash in flight_custom_version (no 6-DoF tag), SYS_STATUS
  sets PREARM_CHECK in `health` only, MISSION_CURRENT says UINT16_MAX items (no mission).

The vehicle is a point mass on a 50 Hz wall clock: good enough to tell a command that flies
from one that drops it.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field

from pymavlink import mavutil

from common.wire import modes as px4_modes
from common.wire.mavlink import MAV

M = MAV
G = 9.81
HOME = (47.397742, 8.545594, 488.0)  # PX4's SITL home
GIT_HASH = bytes.fromhex("f2471861a0b1c2d3")
MPC_Z_VEL_MAX_DN, MPC_Z_VEL_MAX_UP, MPC_LAND_SPEED, XY_SPEED = 1.0, 3.0, 0.7, 3.0
PARAMS = {"MPC_Z_VEL_MAX_DN": MPC_Z_VEL_MAX_DN, "MIS_TAKEOFF_ALT": 2.5}  # PX4's defaults: 1, 2.5
OFFBOARD_LOSS_S = 1.0
IGNORE_THROTTLE = 1 << 6
DT = 0.02


def _mode(name: str) -> int:
    mode = px4_modes.by_name(name)
    assert mode is not None, name
    return mode.custom_mode


OFFBOARD, LOITER, TAKEOFF, LAND, RTL = (_mode(n) for n in
                                        ("OFFBOARD", "HOLD", "TAKEOFF", "LAND", "RTL"))
POSCTL = _mode("POSCTL")


@dataclass
class Received:
    """What the vehicle was sent: (monotonic s, message type) and the modes it entered."""

    messages: list[tuple[float, str]] = field(default_factory=list)
    modes: list[int] = field(default_factory=list)

    def count(self, kind: str, after: float = 0.0) -> int:
        return sum(1 for t, k in self.messages if k == kind and t >= after)


class ScriptedPX4Vehicle:
    """PX4 on `udpout:127.0.0.1:port` (the station listens with udpin); starts landed and
    disarmed at home, or `airborne_m` up in AUTO.LOITER, armed."""

    def __init__(self, port: int, *, airborne_m: float = 0.0,
                 origin_below_home_m: float = 0.0, raises_takeoff: bool = False) -> None:
        self.conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=1,
                                               source_component=1, dialect="common")
        self.p = [0.0, 0.0, -airborne_m]  # NED, m
        # the local origin this far below home (ArduPilot's is where its first fix was):
        # GLOBAL_POSITION_INT's height above home, sent before each LOCAL_POSITION_NED
        self.origin_below_home_m = origin_below_home_m
        # PX4 up to 1.14: a takeoff below home + MIS_TAKEOFF_ALT raised to it, and said so
        # after the answer (1.15 and later take the altitude as given)
        self.raises_takeoff = raises_takeoff
        self.v = [0.0, 0.0, 0.0]
        self.yaw = 0.0
        self.armed = airborne_m > 0.0
        self.mode = LOITER if self.armed else POSCTL
        self.hold = list(self.p)
        self.target: list[float] | None = None  # OFFBOARD position target
        self.yaw_target: float | None = None
        self.attitude_thrust: float | None = None  # OFFBOARD attitude control (thrust)
        self.offboard_at = -math.inf  # the latest set-point (monotonic s)
        self.takeoff_z = 0.0
        self.takeoff_asked_m: float | None = None  # NAV_TAKEOFF's p7 above home
        self.cut_thrust_below_m: float | None = None  # a fault: motors off above this
        self.motors_dead = False  # a fault: no thrust, whatever the mode
        self.got = Received()
        self.errors: list[BaseException] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="scripted-px4", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ plumbing

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        self.conn.close()
        assert not self.errors, self.errors

    def _run(self) -> None:
        next_tick = time.monotonic()
        ticks = 0
        try:
            while not self._stop.is_set():
                msg = self.conn.recv_match(blocking=True, timeout=0.005)
                while msg is not None:
                    if msg.get_type() != "BAD_DATA":
                        self.got.messages.append((time.monotonic(), msg.get_type()))
                        self._handle(msg)
                    msg = self.conn.recv_match(blocking=False)
                if time.monotonic() >= next_tick:
                    next_tick += DT
                    ticks += 1
                    self._step(DT)
                    self._telemetry(ticks)
        except BaseException as exc:  # surfaced by close()
            self.errors.append(exc)

    # ------------------------------------------------------------------ physics and modes

    def _set_mode(self, mode: int) -> None:
        if mode != self.mode:
            self.mode = mode
            self.got.modes.append(mode)
        self.hold = list(self.p)
        if mode != OFFBOARD:
            self.attitude_thrust = None

    def _step(self, dt: float) -> None:
        now = time.monotonic()
        if self.mode == OFFBOARD and now - self.offboard_at > OFFBOARD_LOSS_S:
            self._set_mode(LOITER)  # offboard lost: PX4's default failsafe holds
        if not self.armed:
            self.v = [0.0, 0.0, 0.0]
            return
        if self.cut_thrust_below_m is not None and -self.p[2] >= self.cut_thrust_below_m:
            self.motors_dead, self.cut_thrust_below_m = True, None  # whatever the mode
        if self.motors_dead:
            self.v[2] += G * dt
            self.v[0] = self.v[1] = 0.0
        elif self.mode == OFFBOARD and self.attitude_thrust is not None:
            # attitude control alone: level attitude, thrust as given (0.5 hovers)
            self.v[2] += (G - self.attitude_thrust / 0.5 * G) * dt
            self.v[0] = self.v[1] = 0.0
        else:
            goal = self._goal()
            self._track(goal, dt)
        for i in range(3):
            self.p[i] += self.v[i] * dt
        if self.p[2] >= 0.0:  # the ground
            self.p[2], self.v = 0.0, [0.0, 0.0, 0.0]
            if self.mode in (LAND, RTL) or self.motors_dead or (
                    self.mode == OFFBOARD and self.attitude_thrust is not None):
                self.armed = False  # landed (or crashed): PX4's land detector disarms

    def _goal(self) -> list[float]:
        if self.mode == OFFBOARD and self.target is not None:
            return self.target
        if self.mode == TAKEOFF:
            if abs(self.p[2] - self.takeoff_z) < 0.05:
                self._set_mode(LOITER)
            return [self.hold[0], self.hold[1], self.takeoff_z]
        if self.mode == LAND:
            return [self.hold[0], self.hold[1], 1.0]
        if self.mode == RTL:
            if math.hypot(self.p[0], self.p[1]) > 0.1:
                return [0.0, 0.0, min(self.p[2], -3.0)]
            return [0.0, 0.0, 1.0]
        return self.hold

    def _track(self, goal: list[float], dt: float) -> None:
        dn, de, dd = (goal[i] - self.p[i] for i in range(3))
        horiz = math.hypot(dn, de)
        speed = min(XY_SPEED, 1.5 * horiz)
        vn, ve = (speed * dn / horiz, speed * de / horiz) if horiz > 1e-9 else (0.0, 0.0)
        down_limit = MPC_LAND_SPEED if self.mode in (LAND, RTL) and horiz <= 0.1 \
            else MPC_Z_VEL_MAX_DN
        vd = max(-MPC_Z_VEL_MAX_UP, min(down_limit, 1.5 * dd))
        self.v = [vn, ve, vd]
        if self.mode == OFFBOARD and self.yaw_target is not None:
            err = math.remainder(self.yaw_target - self.yaw, 2.0 * math.pi)
            self.yaw += max(-2.0 * dt, min(2.0 * dt, err))

    # ------------------------------------------------------------------ messages in

    def _ack(self, msg, result: int = M.MAV_RESULT_ACCEPTED) -> None:
        self.conn.mav.command_ack_send(msg.command, result)

    def _handle(self, msg) -> None:
        kind = msg.get_type()
        if kind == "SET_POSITION_TARGET_LOCAL_NED":
            self.offboard_at = time.monotonic()
            self.target = [msg.x, msg.y, msg.z]
            self.yaw_target = None if msg.type_mask & (1 << 10) else msg.yaw
            self.attitude_thrust = None  # position control again
        elif kind == "SET_ATTITUDE_TARGET":
            self.offboard_at = time.monotonic()
            self.attitude_thrust = 0.0 if msg.type_mask & IGNORE_THROTTLE else msg.thrust
        elif kind == "COMMAND_LONG":
            self._command(msg)
        elif kind == "PARAM_REQUEST_READ":
            if msg.param_id in PARAMS:
                self.conn.mav.param_value_send(msg.param_id.encode(), PARAMS[msg.param_id],
                                               M.MAV_PARAM_TYPE_REAL32, len(PARAMS),
                                               list(PARAMS).index(msg.param_id))

    def _command(self, msg) -> None:
        cmd = msg.command
        if cmd == M.MAV_CMD_COMPONENT_ARM_DISARM:
            if msg.param1 == 1.0 and self.p[2] < -0.1:
                self._ack(msg, M.MAV_RESULT_DENIED)
                return
            self.armed = msg.param1 == 1.0
            self._ack(msg)
        elif cmd == M.MAV_CMD_DO_SET_MODE:
            wanted = (int(msg.param2) << 16) | (int(msg.param3) << 24)
            if int(msg.param2) != px4_modes.MAIN_AUTO:
                wanted &= 0x00FF0000
            if wanted == OFFBOARD and time.monotonic() - self.offboard_at > OFFBOARD_LOSS_S:
                self._ack(msg, M.MAV_RESULT_TEMPORARILY_REJECTED)  # no set-points yet
                return
            self._ack(msg)
            self._set_mode(wanted)
        elif cmd == M.MAV_CMD_NAV_TAKEOFF:
            if not self.armed or self.p[2] < -0.1:
                self._ack(msg, M.MAV_RESULT_TEMPORARILY_REJECTED)
                return
            self._ack(msg)
            self.takeoff_asked_m = msg.param7 - HOME[2]
            self.takeoff_z = -self.takeoff_asked_m
            least = PARAMS["MIS_TAKEOFF_ALT"]
            if self.raises_takeoff and -self.takeoff_z < least:
                self.takeoff_z = -least
                self.conn.mav.statustext_send(M.MAV_SEVERITY_CRITICAL,
                                              f"Using minimum takeoff altitude: {least:.2f} m"
                                              .encode())
            self._set_mode(TAKEOFF)
        elif cmd == M.MAV_CMD_REQUEST_MESSAGE:
            self._ack(msg)
            self._requested(int(msg.param1))
        else:
            self._ack(msg, M.MAV_RESULT_UNSUPPORTED)

    def _requested(self, msg_id: int) -> None:
        mav = self.conn.mav
        if msg_id == M.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            mav.autopilot_version_send(0xE4EF, (1 << 24) | (16 << 16), 0, 0, 0,
                                       list(GIT_HASH), [0] * 8, [0] * 8, 0, 0, 1)
        elif msg_id == M.MAVLINK_MSG_ID_HOME_POSITION:
            lat, lon, alt = HOME
            mav.home_position_send(round(lat * 1e7), round(lon * 1e7), round(alt * 1e3),
                                   0, 0, 0, [1, 0, 0, 0], 0, 0, 0)
        elif msg_id == M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE:
            self._extended()
        elif msg_id == M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT:
            self._global()

    # ------------------------------------------------------------------ messages out

    def _extended(self) -> None:
        landed = M.MAV_LANDED_STATE_ON_GROUND if self.p[2] >= -0.05 and not any(self.v) \
            else M.MAV_LANDED_STATE_IN_AIR
        self.conn.mav.extended_sys_state_send(0, landed)

    def _global(self) -> None:
        lat, lon, alt = HOME
        self.conn.mav.global_position_int_send(
            0, round((lat + self.p[0] / 111_111.0) * 1e7),
            round((lon + self.p[1] / (111_111.0 * math.cos(math.radians(lat)))) * 1e7),
            round((alt - self.p[2]) * 1e3),
            round((-self.p[2] - self.origin_below_home_m) * 1e3), round(self.v[0] * 100),
            round(self.v[1] * 100), round(self.v[2] * 100), 0)

    def _telemetry(self, ticks: int) -> None:
        mav = self.conn.mav
        if self.origin_below_home_m:
            self._global()
        mav.local_position_ned_send(0, *self.p, *self.v)
        half = self.yaw / 2.0
        mav.attitude_quaternion_send(0, math.cos(half), 0.0, 0.0, math.sin(half), 0, 0, 0)
        if ticks % 5 == 0:
            base = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (M.MAV_MODE_FLAG_SAFETY_ARMED
                                                          if self.armed else 0)
            mav.heartbeat_send(M.MAV_TYPE_HEXAROTOR, M.MAV_AUTOPILOT_PX4, base, self.mode,
                               M.MAV_STATE_ACTIVE if self.armed else M.MAV_STATE_STANDBY)
            self._global()
            self._extended()
            sensors = M.MAV_SYS_STATUS_SENSOR_3D_GYRO | M.MAV_SYS_STATUS_SENSOR_3D_ACCEL
            mav.sys_status_send(sensors, sensors, sensors | M.MAV_SYS_STATUS_PREARM_CHECK,
                                0, 0, -1, -1, 0, 0, 0, 0, 0, 0)
            mav.mission_current_send(0, 65535, M.MISSION_STATE_NO_MISSION)
