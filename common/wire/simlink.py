"""The simulator link's hot messages, packed and parsed without pymavlink's object
machinery: ODOMETRY (SITL -> FCU: the state, or with a sensor profile the motion-capture
pose), HIL_SENSOR (SITL -> FCU: IMU, magnetometer, barometer) and HIL_ACTUATOR_CONTROLS
(FCU -> SITL, command).

Frames are standard MAVLink 2 (magic 0xFD, trailing-zero payload truncation, CRC-16/MCRF4XX
with the message's CRC_EXTRA); layouts and CRC_EXTRA come from pymavlink's `common` dialect,
so any MAVLink 2 parser reads what we write and we read any MAVLink 2 sender. Channel map of
HIL_ACTUATOR_CONTROLS (docs/simulator-link.md): controls[0..5] = rotor speed / w_max (0..1),
controls[6..11] = tilt angle in rad (continuous after unwrapping, a documented departure
from the -1..1 convention of this SITL-only message); mode has SAFETY_ARMED when armed;
flags bit 0 = lockstep.
"""

from __future__ import annotations

import struct
from typing import TYPE_CHECKING, Literal, NamedTuple, overload

from common.wire.mavlink import MAV

if TYPE_CHECKING:
    from _typeshed import ReadableBuffer

try:
    from fastcrc.crc16 import mcrf4xx as _crc
except ImportError:  # pragma: no cover - pymavlink depends on fastcrc; keep a fallback
    from pymavlink.generator.mavcrc import x25crc_slow

    def _crc(data: ReadableBuffer, initial: int | None = None) -> int:
        c = x25crc_slow()
        c.crc = 0xFFFF if initial is None else initial
        c.accumulate(bytes(data))
        return int(c.crc)

_ODO = MAV.MAVLink_odometry_message
_HAC = MAV.MAVLink_hil_actuator_controls_message
_HIL = MAV.MAVLink_hil_sensor_message
_TSY = MAV.MAVLink_timesync_message
ODOMETRY_ID, HIL_ACTUATOR_CONTROLS_ID, HIL_SENSOR_ID = _ODO.id, _HAC.id, _HIL.id
TIMESYNC_ID = _TSY.id
_ODO_STRUCT = struct.Struct(_ODO.unpacker.format)
_HAC_STRUCT = struct.Struct(_HAC.unpacker.format)
_HIL_STRUCT = struct.Struct(_HIL.unpacker.format)
_TSY_STRUCT = struct.Struct(_TSY.unpacker.format)  # tc1, ts1 (int64, ns)
_HEADER = struct.Struct("<BBBBBBBHB")  # magic, len, incompat, compat, seq, sys, comp, id
_ZERO_COV = (0.0,) * 21
_NAN_COV = (float("nan"),) + (0.0,) * 20  # first element NaN: covariance unknown
LOCKSTEP_FLAG = 1
MODE_ARMED = MAV.MAV_MODE_FLAG_SAFETY_ARMED


NAN_COVARIANCE = _NAN_COV


class Odometry(NamedTuple):
    """State on the wire: local NED position, attitude NED->FRD, FRD body velocity and rates.

    As the simulator's exact state: estimator_type NAIVE, covariances unknown. As a
    motion-capture pose (as PX4 takes external vision): estimator_type MOCAP, time_usec the
    capture time, velocity and rates NaN (not measured), the pose covariance's diagonal
    (upper-right triangle, row-major: indices 0, 6, 11 position, 15, 18, 20 attitude)."""

    time_usec: int
    p_ned_m: tuple[float, float, float]
    q_ned_frd: tuple[float, float, float, float]
    v_frd_m_s: tuple[float, float, float]
    omega_frd_rad_s: tuple[float, float, float]
    estimator_type: int = MAV.MAV_ESTIMATOR_TYPE_NAIVE
    pose_covariance: tuple[float, ...] = _NAN_COV
    frame_id: int = MAV.MAV_FRAME_LOCAL_NED
    child_frame_id: int = MAV.MAV_FRAME_BODY_FRD


def pose_covariance(pos_var_m2: float, att_var_rad2: float) -> tuple[float, ...]:
    """The 21-element upper-triangle pose covariance with a diagonal only."""
    cov = [0.0] * 21
    for i in (0, 6, 11):
        cov[i] = pos_var_m2
    for i in (15, 18, 20):
        cov[i] = att_var_rad2
    return tuple(cov)


class HilSensor(NamedTuple):
    """HIL_SENSOR: one IMU sample (FRD) with the magnetometer (gauss, FRD) and barometer
    fields; `fields_updated` says which of them are new in this sample (HIL_SENSOR_*)."""

    time_usec: int
    acc_frd_m_s2: tuple[float, float, float]
    gyro_frd_rad_s: tuple[float, float, float]
    mag_frd_gauss: tuple[float, float, float]
    abs_pressure_hpa: float
    pressure_alt_m: float
    temperature_c: float
    fields_updated: int


class ActuatorControls(NamedTuple):
    time_usec: int
    controls: tuple[float, ...]  # 16 floats
    mode: int
    flags: int


_CRC_EXTRA_BYTES = [bytes([i]) for i in range(256)]
_CRC_STRUCT = struct.Struct("<H")


def _frame(msg_id: int, crc_extra: int, payload: bytes, seq: int, sysid: int,
           compid: int) -> bytes:
    payload = payload.rstrip(b"\x00") or b"\x00"
    header = _HEADER.pack(0xFD, len(payload), 0, 0, seq & 0xFF, sysid, compid,
                          msg_id & 0xFFFF, msg_id >> 16)
    body = header + payload
    return body + _CRC_STRUCT.pack(_crc(_CRC_EXTRA_BYTES[crc_extra], _crc(body[1:])))


def pack_timesync(tc1_ns: int, ts1_ns: int, seq: int, sysid: int, compid: int) -> bytes:
    """TIMESYNC (MAVLink's round-trip message): a request has tc1 = 0 and ts1 = the
    sender's clock; the answer carries tc1 = the responder's clock and ts1 echoed."""
    return _frame(TIMESYNC_ID, _TSY.crc_extra, _TSY_STRUCT.pack(tc1_ns, ts1_ns), seq, sysid,
                  compid)


def unpack_timesync(payload: bytes) -> tuple[int, int]:
    """(tc1, ts1) of a TIMESYNC payload (zero-extended, as `split_frames` returns it)."""
    return _TSY_STRUCT.unpack_from(payload)


def _odometry_payload(o: Odometry) -> bytes:
    return _ODO_STRUCT.pack(o.time_usec, *o.p_ned_m, *o.q_ned_frd, *o.v_frd_m_s,
                            *o.omega_frd_rad_s, *o.pose_covariance, *_NAN_COV,
                            o.frame_id, o.child_frame_id, 0, o.estimator_type, 100)


def _hil_sensor_payload(h: HilSensor) -> bytes:
    return _HIL_STRUCT.pack(h.time_usec, *h.acc_frd_m_s2, *h.gyro_frd_rad_s, *h.mag_frd_gauss,
                            h.abs_pressure_hpa, 0.0, h.pressure_alt_m, h.temperature_c,
                            h.fields_updated, 0)


def pack_hil_sensor(h: HilSensor, seq: int, sysid: int, compid: int) -> bytes:
    return _frame(HIL_SENSOR_ID, _HIL.crc_extra, _hil_sensor_payload(h), seq, sysid, compid)


def unpack_hil_sensor(payload: bytes) -> HilSensor:
    v = _HIL_STRUCT.unpack(payload)
    return HilSensor(v[0], (v[1], v[2], v[3]), (v[4], v[5], v[6]), (v[7], v[8], v[9]), v[10],
                     v[12], v[13], v[14])


def through_wire_hil_sensor(h: HilSensor) -> HilSensor:
    """What the receiver of `h` reads: its floats rounded to float32 (in-process runs)."""
    return unpack_hil_sensor(_hil_sensor_payload(h))


def pack_odometry(o: Odometry, seq: int, sysid: int, compid: int) -> bytes:
    return _frame(ODOMETRY_ID, _ODO.crc_extra, _odometry_payload(o), seq, sysid, compid)


def pack_actuator_controls(a: ActuatorControls, seq: int, sysid: int, compid: int) -> bytes:
    payload = _HAC_STRUCT.pack(a.time_usec, a.flags, *a.controls, a.mode)
    return _frame(HIL_ACTUATOR_CONTROLS_ID, _HAC.crc_extra, payload, seq, sysid, compid)


def through_wire_odometry(o: Odometry) -> Odometry:
    """What the receiver of `o` reads: its floats rounded to float32 (in-process runs)."""
    return unpack_odometry(_odometry_payload(o))


def through_wire_controls(a: ActuatorControls) -> ActuatorControls:
    """What the receiver of `a` reads: its floats rounded to float32 (in-process runs)."""
    return unpack_actuator_controls(_HAC_STRUCT.pack(a.time_usec, a.flags, *a.controls,
                                                     a.mode))


class Frame(NamedTuple):
    msg_id: int
    sysid: int
    compid: int
    payload: bytes  # zero-extended to the message's full length
    raw: bytes


_HOT = {ODOMETRY_ID, HIL_ACTUATOR_CONTROLS_ID, HIL_SENSOR_ID, TIMESYNC_ID}
# Every message of the dialect: (CRC_EXTRA as a byte, full payload length). A frame can be
# checked only when its message is known: a header naming any other message is rejected
# (byte by byte, as corruption), so that it cannot swallow the valid frames after it.
_KNOWN = {msg_id: (bytes([cls.crc_extra]), cls.unpacker.size)
          for msg_id, cls in MAV.mavlink_map.items()}
_SIGNED = 0x01  # MAVLINK_IFLAG_SIGNED, the only incompatibility flag defined
_SIGNATURE_LEN = 13


@overload
def split_frames(data: bytes, *, stream: Literal[False] = False) -> tuple[list[Frame], int]: ...


@overload
def split_frames(data: bytes, *, stream: Literal[True]) -> tuple[list[Frame], int, bytes]: ...


def split_frames(data: bytes, *, stream: bool = False) -> tuple[list[Frame], int] | tuple[
        list[Frame], int, bytes]:
    """Valid MAVLink 2 frames of the dialect in a datagram, and the count of rejected bytes.

    Every returned frame has a correct CRC. Frames of the hot pair come with their payload
    zero-extended to the message's full length; other messages of the dialect with an empty
    payload and their raw bytes, so that a general parser can take them. Everything else is
    rejected: bytes before a start marker, headers that name no message of the dialect, a
    payload longer than the message, unknown incompatibility flags, a wrong CRC and (in a
    datagram) a frame cut short. After a rejected header the search for a frame resumes at
    the next byte, so a corrupted header never hides a valid frame behind it. Each byte of
    `data` is either in a returned frame's `raw` or counted as rejected (or, with
    `stream=True`, in the tail).

    With `stream=True` (TCP, serial) a plausible frame cut at the end is not rejected but
    returned as the third element, to be prepended to the next chunk.
    """
    frames: list[Frame] = []
    rejected = 0
    i, n = 0, len(data)
    while i < n:
        if data[i] != 0xFD:
            j = data.find(b"\xfd", i + 1)
            rejected += (j if j >= 0 else n) - i
            if j < 0:
                break
            i = j
            continue
        if n - i < 10:  # the header is not complete
            if stream:
                return frames, rejected, data[i:]
            rejected += n - i
            break
        length, incompat = data[i + 1], data[i + 2]
        msg_id = data[i + 7] | (data[i + 8] << 8) | (data[i + 9] << 16)
        known = _KNOWN.get(msg_id)
        if known is None or length > known[1] or incompat & ~_SIGNED:
            rejected += 1  # not a frame we can check: look for one at the next byte
            i += 1
            continue
        body_end = i + 10 + length
        end = body_end + 2 + (_SIGNATURE_LEN if incompat & _SIGNED else 0)
        if end > n:
            if stream:
                return frames, rejected, data[i:]
            rejected += 1
            i += 1
            continue
        crc_extra, size = known
        crc = _crc(crc_extra, _crc(data[i + 1:body_end]))
        if crc != (data[body_end] | (data[body_end + 1] << 8)):
            rejected += 1
            i += 1
            continue
        payload = data[i + 10:body_end] + bytes(size - length) if msg_id in _HOT else b""
        frames.append(Frame(msg_id, data[i + 5], data[i + 6], payload, data[i:end]))
        i = end
    if stream:
        return frames, rejected, b""
    return frames, rejected


class FrameReader:
    """Per-peer frame splitting: whole datagrams for UDP, a carried tail for streams."""

    def __init__(self, stream: bool) -> None:
        self.stream = stream
        self.tails: dict[object, bytes] = {}

    def feed(self, peer: object, data: bytes) -> tuple[list[Frame], int]:
        if not self.stream:
            return split_frames(data)
        frames, rejected, tail = split_frames(self.tails.pop(peer, b"") + data, stream=True)
        if tail:
            self.tails[peer] = tail[-512:]
        return frames, rejected


def unpack_odometry(payload: bytes) -> Odometry:
    v = _ODO_STRUCT.unpack(payload)
    return Odometry(v[0], (v[1], v[2], v[3]), (v[4], v[5], v[6], v[7]), (v[8], v[9], v[10]),
                    (v[11], v[12], v[13]), v[59], tuple(v[14:35]), v[56], v[57])


def unpack_actuator_controls(payload: bytes) -> ActuatorControls:
    v = _HAC_STRUCT.unpack(payload)
    return ActuatorControls(v[0], tuple(v[2:18]), v[18], v[1])
