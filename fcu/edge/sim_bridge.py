"""The FCU's simulator link: ODOMETRY in (checked and converted to ENU/FLU), stored answers,
HIL_ACTUATOR_CONTROLS out (docs/simulator-link.md).

Lockstep: a state already answered (same `time_usec`) gets the stored answer again, without
stepping anything (so loss changes timing, never results); an older state is stale and
dropped. With the estimator (EKF_EN = 1) the same holds for HIL_SENSOR, whose sample at the
end of a control period stands for the state; ODOMETRY is then an external pose (motion
capture) for the estimator, stamped with its capture time, each taken once.

A state no vehicle can be in (not finite, not a unit quaternion, absurdly far or fast) is
refused and counted: a stream of them is state loss for the failsafe.
"""

from __future__ import annotations

import math
import select
import statistics
import time
from typing import NamedTuple

from common.frames import frd_to_flu, ned_to_enu, q_ned_frd_to_enu_flu
from common.links import Link
from common.quaternion import Quat, Vec3
from common.wire.simlink import (
    HIL_SENSOR_ID,
    LOCKSTEP_FLAG,
    MODE_ARMED,
    ODOMETRY_ID,
    TIMESYNC_ID,
    ActuatorControls,
    FrameReader,
    HilSensor,
    Odometry,
    pack_actuator_controls,
    pack_timesync,
    unpack_hil_sensor,
    unpack_odometry,
    unpack_timesync,
)
from fcu.estimator.inputs import ImuInput, PoseInput
from fcu.pipeline import StepOutput
from fcu.stages import VehicleState

MAX_POSITION_M = 1e6  # a state farther from the origin is refused as invalid
MAX_RATE = 1e4  # m/s and rad/s: a state moving faster is refused as invalid
CONTROLS = 16  # HIL_ACTUATOR_CONTROLS carries 16 floats


class RoundTrips(NamedTuple):
    """TIMESYNC round trips with the simulator (`SimBridge.round_trips`)."""

    samples_us: list[float]
    lost: int  # requests never answered
    late: int  # requests answered after their `timeout_s` (not timed; counted apart)
    other: list[tuple[object, bytes]]  # what else came meanwhile, to be handled as usual

    @property
    def median_us(self) -> float | None:
        return statistics.median(self.samples_us) if len(self.samples_us) >= 10 else None

    def quantile_us(self, q: float) -> float | None:
        ordered = sorted(self.samples_us)
        return ordered[min(len(ordered) - 1, int(q * len(ordered)))] if ordered else None

    def summary(self) -> dict[str, float | int | None]:
        """As the FCU's stats file records it (`sim_rtt`)."""
        return {"median_us": self.median_us, "samples": len(self.samples_us),
                "lost": self.lost, "late": self.late, "p10_us": self.quantile_us(0.1),
                "p90_us": self.quantile_us(0.9)}


class StateSample(NamedTuple):
    stamp_us: int
    state: VehicleState


class Resent(NamedTuple):
    """The newest state or IMU sample again (lockstep: a re-send; see SimBridge.repeat)."""

    t_us: int


def valid_state(p: Vec3, q: Quat, v: Vec3, w: Vec3) -> bool:
    """Whether a vehicle can be in this state (position, attitude, body velocity and rate,
    in any frame: the checks do not depend on it): all finite, a unit quaternion, not
    absurdly far or fast."""
    # One sum for the finiteness of all 13 values: NaN and inf propagate through it, and a
    # sum that overflows needs values far beyond the limits checked below anyway.
    if not math.isfinite(sum(p) + sum(q) + sum(v) + sum(w)):
        return False
    qw, qx, qy, qz = q
    return not (abs(math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz) - 1.0) > 0.01 or
                max(abs(p[0]), abs(p[1]), abs(p[2])) > MAX_POSITION_M or
                max(abs(v[0]), abs(v[1]), abs(v[2]), abs(w[0]), abs(w[1]),
                    abs(w[2])) > MAX_RATE)


def state_from_odometry(odo: Odometry) -> VehicleState | None:
    """ENU/FLU state of an ODOMETRY, or None when no vehicle can be in it."""
    if not valid_state(odo.p_ned_m, odo.q_ned_frd, odo.v_frd_m_s, odo.omega_frd_rad_s):
        return None
    return VehicleState(ned_to_enu(odo.p_ned_m), q_ned_frd_to_enu_flu(odo.q_ned_frd),
                        frd_to_flu(odo.v_frd_m_s), frd_to_flu(odo.omega_frd_rad_s))


def imu_from_hil_sensor(h: HilSensor) -> ImuInput:
    """The IMU sample of a HIL_SENSOR in FLU (not checked: the estimator refuses NaN)."""
    return ImuInput(h.time_usec, frd_to_flu(h.gyro_frd_rad_s), frd_to_flu(h.acc_frd_m_s2))


def pose_from_odometry(odo: Odometry) -> PoseInput | None:
    """The external pose of an ODOMETRY (ENU/FLU, its capture time and variances), or None
    when its position or attitude is not finite or the quaternion not a unit one."""
    cov = odo.pose_covariance
    return pose_from_wire(odo.time_usec, odo.p_ned_m, odo.q_ned_frd, cov[0], cov[15])


def pose_from_wire(time_usec: int, p_ned_m: Vec3, q_ned_frd: Quat, pos_var: float,
                   att_var: float) -> PoseInput | None:
    """`pose_from_odometry` on the fields it reads: the capture time, position, attitude
    and the pose covariance's first position and attitude variances."""
    px, py, pz = p_ned_m
    qw, qx, qy, qz = q_ned_frd
    isfinite = math.isfinite
    if not (isfinite(px) and isfinite(py) and isfinite(pz) and isfinite(qw)
            and isfinite(qx) and isfinite(qy) and isfinite(qz)):
        return None
    if abs(math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz) - 1.0) > 0.01 or \
            max(abs(px), abs(py), abs(pz)) > MAX_POSITION_M:
        return None
    return PoseInput(time_usec, (py, px, -pz), q_ned_frd_to_enu_flu(q_ned_frd),
                     pos_var if isfinite(pos_var) and pos_var > 0.0 else math.nan,
                     att_var if isfinite(att_var) and att_var > 0.0 else math.nan)


def actuator_controls(out: StepOutput, w_max: float, lockstep: bool) -> ActuatorControls:
    """controls[0..n) = speed / w_max, controls[n..2n) = tilt in rad (docs/simulator-link.md)."""
    speeds = tuple(s / w_max for s in out.speed_rad_s)
    controls = (*speeds, *out.tilt_rad, *(0.0,) * (CONTROLS - 2 * len(speeds)))
    return ActuatorControls(out.t_us, controls, MODE_ARMED if out.armed else 0,
                            LOCKSTEP_FLAG if lockstep else 0)


class SimBridge:
    def __init__(self, link: Link, system_id: int, component_id: int, *, lockstep: bool,
                 w_max: float) -> None:
        self.link = link
        self.system_id = system_id
        self.component_id = component_id
        self.lockstep = lockstep
        self.w_max = w_max
        self.reader = FrameReader(link.is_stream)
        self.answered_us = -1
        self.answer = b""
        self.seq = 0
        self.resent_answers = 0
        self.rejected_bytes = 0
        self.ignored_messages = 0
        self.use_estimator = False  # EKF_EN: HIL_SENSOR and poses in, not the exact state
        self.state_us = -1  # the newest state taken (lockstep: each is stepped once)
        self.imu_us = -1  # the newest IMU sample taken
        self.pose_us = -1  # the newest pose capture taken

    def receive(self, peer: object,
                data: bytes) -> list[StateSample | ImuInput | PoseInput | Resent]:
        """New inputs of our vehicle in a datagram, in order: valid states (exact state
        input), or IMU samples and poses (estimator); duplicates answered here."""
        frames, rejected = self.reader.feed(peer, data)
        if rejected:
            self.rejected_bytes += rejected
        out: list[StateSample | ImuInput | PoseInput | Resent] = []
        for f in frames:
            if f.msg_id != ODOMETRY_ID and f.msg_id != HIL_SENSOR_ID:
                continue
            if f.sysid != self.system_id:
                self.ignored_messages += 1  # another vehicle's simulator: not our state
                continue
            if self.use_estimator:
                item = self._estimator_input(f.msg_id, f.payload)
                if item is not None:
                    out.append(item)
                continue
            if f.msg_id != ODOMETRY_ID:
                continue  # HIL_SENSOR without the estimator: not used
            odo = unpack_odometry(f.payload)
            if self.lockstep and odo.time_usec == self.state_us:
                out.append(Resent(odo.time_usec))  # taken once: `repeat` answers it
                continue
            if self.lockstep and odo.time_usec < self.state_us:
                self.ignored_messages += 1  # stale
                continue
            state = state_from_odometry(odo)
            if state is None:
                self.ignored_messages += 1
                continue
            self.state_us = odo.time_usec
            out.append(StateSample(odo.time_usec, state))
        return out

    def _estimator_input(self, msg_id: int,
                         payload: bytes) -> ImuInput | PoseInput | Resent | None:
        if msg_id == HIL_SENSOR_ID:
            h = unpack_hil_sensor(payload)
            if self.lockstep and h.time_usec == self.imu_us:
                return Resent(h.time_usec)  # taken once: `repeat` answers it
            if h.time_usec <= self.imu_us:
                self.ignored_messages += 1  # a re-sent or stale sample: taken once
                return None
            self.imu_us = h.time_usec
            return imu_from_hil_sensor(h)
        odo = unpack_odometry(payload)
        if odo.time_usec <= self.pose_us:
            self.ignored_messages += 1
            return None
        pose = pose_from_odometry(odo)
        if pose is None:
            self.ignored_messages += 1
            return None
        self.pose_us = odo.time_usec
        return pose

    def round_trips(self, n: int, *, timeout_s: float = 0.05, max_lost: int = 3,
                    budget_s: float = 1.0) -> RoundTrips:
        """`n` round trips of a TIMESYNC request (MAVLink's round-trip message, 28 bytes on
        the wire) to the simulator and its answer, one at a time on the simulator link's own
        socket, waiting for each in `select` as any blocking receiver does: the transport's
        round trip between the two processes, with the least work on either side (a
        pre-built frame each way; the simulator answers before anything else).

        A request unanswered within `timeout_s` counts as lost until its answer comes, during
        a later wait (a process preempted on a busy machine): then it counts as late, untimed,
        since another request was already out. Stops after `max_lost` requests lost at once
        (a simulator that does not answer TIMESYNC) or after `budget_s`. Everything else that
        arrives meanwhile is returned in `other`, in order, for the caller to handle."""
        link = self.link
        stream = link.is_stream
        reader = FrameReader(stream)  # sees the bytes the bridge's reader will see later
        samples: list[float] = []
        other: list[tuple[object, bytes]] = []
        timed_out: set[int] = set()  # stamps of requests not answered in time
        late = 0
        clock = time.monotonic_ns
        end = clock() + round(budget_s * 1e9)
        while len(samples) < n and len(timed_out) < max_lost and clock() < end:
            self.seq = (self.seq + 1) & 0xFF
            t0 = clock()
            link.send(pack_timesync(0, t0, self.seq, self.system_id, self.component_id))
            deadline = t0 + round(timeout_s * 1e9)
            answered = False
            while not answered:
                left = deadline - clock()
                if left <= 0 or not select.select(link.filenos(), [], [], left * 1e-9)[0]:
                    break
                for peer, data in link.recv():
                    t1 = clock()
                    frames, rejected = reader.feed(peer, data)
                    only_answer = not stream and not rejected and len(frames) == 1
                    for f in frames:
                        tc1, ts1 = (unpack_timesync(f.payload) if f.msg_id == TIMESYNC_ID
                                    and f.sysid == self.system_id else (0, 0))
                        if tc1 != 0 and ts1 == t0 and not answered:
                            samples.append((t1 - t0) * 1e-3)
                            answered = True
                        elif tc1 != 0 and ts1 in timed_out:
                            timed_out.discard(ts1)
                            late += 1
                        else:  # not an answer to one of ours: handed on
                            only_answer = False
                    if not only_answer:
                        other.append((peer, data))
            if not answered:
                timed_out.add(t0)
        return RoundTrips(samples, len(timed_out), late, other)

    def repeat(self, t_us: int) -> bool:
        """A state or sample taken before came again (lockstep): if it was answered, send
        the same answer, nothing stepped again (so loss changes timing, never results), and
        return True; False when it is still unanswered (the flight may have started since:
        the caller may step on it now). A stream can deliver a state and its re-send in one
        read: whichever comes second finds the first answered."""
        if t_us != self.answered_us:
            return False
        self.link.send(self.answer)
        self.resent_answers += 1
        return True

    def send(self, out: StepOutput) -> None:
        """Answer the state stamped out.t_us (and remember the answer in lockstep)."""
        self.seq = (self.seq + 1) & 0xFF
        self.answer = pack_actuator_controls(actuator_controls(out, self.w_max, self.lockstep),
                                             self.seq, self.system_id, self.component_id)
        if self.lockstep:
            self.answered_us = out.t_us
        self.link.send(self.answer)
