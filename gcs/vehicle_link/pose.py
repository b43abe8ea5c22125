"""6-DoF pose set-points in local NED (position, attitude q_ned_frd) as MAVLink messages,
the errors of a pose heard from them, and a thread that streams them."""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from common.quaternion import q_angle, q_conj, q_exp, q_mul
from common.wire.mavlink import MAV
from gcs.vehicle_link.session import Session
from gcs.vehicle_link.snapshot import Snapshot

M = MAV


@dataclass(frozen=True)
class PoseTarget:
    """A 6-DoF pose in local NED: position and attitude q_ned_frd."""

    p_ned_m: tuple[float, float, float]
    q_ned_frd: tuple[float, float, float, float]

    @classmethod
    def from_euler_deg(cls, p_ned_m: Sequence[float], roll: float, pitch: float,
                       yaw: float) -> PoseTarget:
        """Z-Y-X (yaw, pitch, roll) in NED/FRD, as ground stations show attitudes."""
        q = q_mul(q_exp((0.0, 0.0, math.radians(yaw))),
                  q_mul(q_exp((0.0, math.radians(pitch), 0.0)),
                        q_exp((math.radians(roll), 0.0, 0.0))))
        north, east, down = p_ned_m
        return cls((north, east, down), q)

    @property
    def yaw_rad(self) -> float:
        """The attitude's Z-Y-X yaw (NED, rad)."""
        return _yaw_rad(self.q_ned_frd)

    def messages(self, session: Session, attitude: bool = True) -> list[Any]:
        """The set-points: the position (yaw ignored) and the attitude target, for a vehicle
        that flies the two together (`common.wire.identity`); or, without `attitude` (PX4's
        OFFBOARD, where an attitude target turns position control off, and ArduPilot's
        GUIDED, where it replaces the position target), the position with the yaw alone."""
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

    def stop(self) -> None:
        """Stop sending, for good; the last message is out when this returns."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)

    def __exit__(self, *_exc: object) -> None:
        self.stop()
