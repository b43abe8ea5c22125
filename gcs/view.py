"""`gcs view`: a live 3D view of the vehicle over the Foxglove WebSocket protocol.

Serves on 127.0.0.1 only, to Foxglove or Lichtblick ("Open connection", Foxglove WebSocket,
ws://127.0.0.1:8765), from one of two sources:

- live (`gcs view [--connect URL]`): the vehicle's standard MAVLink telemetry through a
  `Session`: LOCAL_POSITION_NED + ATTITUDE_QUATERNION (pose), POSITION_TARGET_LOCAL_NED +
  ATTITUDE_TARGET (desired pose), ACTUATOR_OUTPUT_STATUS (actuator[0..5] rotor speeds rad/s,
  actuator[6..11] tilts rad, as this project's FCU reports them), HEARTBEAT (mode, armed);
- replay (`gcs view RUN_DIR [--speed X]`): the run folder's ULog logs, `truth.ulg` (topic
  `dq_truth`: pose, rotor speeds and tilts as they physically were) and `onboard.ulg` (topic
  `dq_onboard`: desired pose, armed flag), on the simulated timeline at X times real time
  (0: as fast as possible, then exit: with `--mcap` this converts a run to MCAP).

Channels (topic, schema, rate in its channel's metadata as `rate_hz`):

| topic | schema | rate |
|---|---|---|
| `/tf` | foxglove.FrameTransforms | 20 Hz |
| `/vehicle/state` | JSON, dqflight.VehicleState | 10 Hz |
| `/path/flown` | foxglove.SceneUpdate (line strip in `world`) | 5 Hz |
| `/path/desired` | foxglove.SceneUpdate (line strip in `world`) | 5 Hz |
| `/airframe` | foxglove.SceneUpdate (body, arms, rotor disks, desired ghost) | 1 Hz |

Rates are per second of wall time live, and per second of the run's timeline in a replay
(so at `--speed 1` also of wall time). Frames: `world` (ENU) -> `base_link` (FLU, the
vehicle), `world` -> `desired` (the desired pose), `base_link` -> `arm_i` (arm i's mounting
Rz(gamma_i) Ry(beta_i) at r_i, turned about the arm axis x by the tilt alpha_i: its z axis
is the thrust direction cos(alpha) e_v + sin(alpha) e_l of `common.geometry`) and `arm_i` ->
`rotor_i` (the rotor hub, identity: spinning it at a few Hz would only alias). Each transform
is stamped with the vehicle time of the sample it comes from (live: time_boot_ms or
time_usec of its message; replay: the log row's time_us), and every message's log time is
the latest vehicle time, so live and replay share one timeline. Paths keep one point per
0.1 s of vehicle time over the last 60 s.

The wire is NED/FRD; everything published is ENU/FLU, converted by `common.frames` only.
The pure parts (samples, transforms, paths, state) are separate from the I/O (server,
session, clocks) at the end of the module.
"""

from __future__ import annotations

import math
import signal
import threading
import time
import tomllib
from collections import deque
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from common.config import ConfigError, VehicleConfig, load_vehicle
from common.frames import ned_to_enu, q_ned_frd_to_enu_flu
from common.geometry import rotor_frames
from common.quaternion import Q_IDENTITY, Quat, Vec3, q_exp, q_mul

if TYPE_CHECKING:
    import foxglove
    from foxglove.messages import FrameTransforms, SceneUpdate

    from gcs.session import Session

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_VEHICLE = ROOT / "config" / "vehicles" / "hexa_tilted.toml"
HOST = "127.0.0.1"  # loopback only, whatever the caller asks
DEFAULT_PORT = 8765

BASE_HZ = 20  # the publishing tick; every channel's rate divides it
RATES_HZ: dict[str, int] = {"/tf": 20, "/vehicle/state": 10, "/path/flown": 5,
                            "/path/desired": 5, "/airframe": 1}
TOPICS = tuple(RATES_HZ)
PATH_WINDOW_US = 60_000_000
PATH_SPACING_US = 100_000
STATE_SCHEMA: dict[str, Any] = {
    "title": "dqflight.VehicleState",
    "type": "object",
    "properties": {
        "time_s": {"type": "number", "description": "vehicle time, s"},
        "source": {"type": "string", "enum": ["live", "replay"]},
        "mode": {"type": ["string", "null"]},
        "armed": {"type": ["boolean", "null"]},
        "rotor_speeds_rad_s": {"type": ["array", "null"], "items": {"type": "number"}},
        "tilts_rad": {"type": ["array", "null"], "items": {"type": "number"}},
        "position_enu_m": {"type": ["array", "null"], "items": {"type": "number"}},
        "desired_position_enu_m": {"type": ["array", "null"], "items": {"type": "number"}},
    },
}


class ViewError(RuntimeError):
    """Bad input for `gcs view`: a run folder, an MCAP path, a port that cannot be used."""


# ---------------------------------------------------------------------------------------
# Pure: samples, transforms, paths, state
# ---------------------------------------------------------------------------------------


class Pose(NamedTuple):
    """A pose in ENU/FLU: position of the body origin, attitude q_enu_flu (w, x, y, z)."""

    p_enu_m: Vec3
    q_enu_flu: Quat


class Transform(NamedTuple):
    """One edge of the frame tree: `child`'s pose in `parent` at vehicle time `time_us`."""

    parent: str
    child: str
    time_us: int
    translation: Vec3
    rotation: Quat  # (w, x, y, z)


class ArmMount(NamedTuple):
    """Arm i's fixed mounting in FLU: rotor position r_i and rotation Rz(gamma) Ry(beta)."""

    r_flu_m: Vec3
    q_flu_arm: Quat


def pose_from_ned(p_ned_m: Sequence[float], q_ned_frd: Sequence[float]) -> Pose:
    """A wire pose (local NED position, attitude q_ned_frd) in ENU/FLU."""
    p = (float(p_ned_m[0]), float(p_ned_m[1]), float(p_ned_m[2]))
    q = (float(q_ned_frd[0]), float(q_ned_frd[1]), float(q_ned_frd[2]), float(q_ned_frd[3]))
    return Pose(ned_to_enu(p), q_ned_frd_to_enu_flu(q))


def arm_mounts(vehicle: VehicleConfig) -> tuple[ArmMount, ...]:
    """The fixed mountings of the arms (positions from `common.geometry.rotor_frames`)."""
    frames = rotor_frames(vehicle)
    return tuple(
        ArmMount(fr.r_flu_m, q_mul(q_exp((0.0, 0.0, gamma)), q_exp((0.0, beta, 0.0))))
        for fr, gamma, beta in zip(frames, vehicle.arm_azimuth_rad, vehicle.arm_elevation_rad,
                                   strict=True))


def arm_transform(mount: ArmMount, tilt_rad: float) -> tuple[Vec3, Quat]:
    """(translation, rotation) of arm_i in base_link: the mounting turned by the tilt about
    the arm axis (the frame's x); its z axis is then the rotor's thrust direction."""
    return mount.r_flu_m, q_mul(mount.q_flu_arm, q_exp((tilt_rad, 0.0, 0.0)))


@dataclass
class Sample:
    """The latest known state of the vehicle (ENU/FLU), each part with its vehicle time."""

    pose: Pose | None = None
    pose_time_us: int | None = None
    desired: Pose | None = None
    desired_time_us: int | None = None
    rotor_speeds_rad_s: tuple[float, ...] | None = None
    tilts_rad: tuple[float, ...] | None = None
    actuator_time_us: int | None = None
    mode: str | None = None
    armed: bool | None = None

    @property
    def time_us(self) -> int | None:
        """The latest vehicle time of any part (None before any timed sample)."""
        times = [t for t in (self.pose_time_us, self.desired_time_us, self.actuator_time_us)
                 if t is not None]
        return max(times) if times else None


def transforms(sample: Sample, mounts: Sequence[ArmMount]) -> list[Transform]:
    """The frame tree of a sample: world->base_link, world->desired, base_link->arm_i,
    arm_i->rotor_i. Arms are drawn untilted until tilts are known."""
    out: list[Transform] = []
    if sample.pose is not None and sample.pose_time_us is not None:
        out.append(Transform("world", "base_link", sample.pose_time_us, *sample.pose))
    if sample.desired is not None and sample.desired_time_us is not None:
        out.append(Transform("world", "desired", sample.desired_time_us, *sample.desired))
    t_arm = sample.actuator_time_us if sample.tilts_rad is not None else sample.time_us
    if t_arm is None:
        return out
    tilts = sample.tilts_rad if sample.tilts_rad is not None else (0.0,) * len(mounts)
    for i, (mount, tilt) in enumerate(zip(mounts, tilts, strict=False)):
        translation, rotation = arm_transform(mount, tilt)
        out.append(Transform("base_link", f"arm_{i}", t_arm, translation, rotation))
        out.append(Transform(f"arm_{i}", f"rotor_{i}", t_arm, (0.0, 0.0, 0.0), Q_IDENTITY))
    return out


class PathBuffer:
    """A bounded path: one point per `spacing_us` of vehicle time over the last
    `window_us`; cleared when time goes back (a new flight or a restarted vehicle)."""

    def __init__(self, window_us: int = PATH_WINDOW_US,
                 spacing_us: int = PATH_SPACING_US) -> None:
        self.window_us = window_us
        self.spacing_us = spacing_us
        self._points: deque[tuple[int, Vec3]] = deque(maxlen=window_us // spacing_us + 1)

    def add(self, time_us: int, p_enu_m: Vec3) -> None:
        if self._points and time_us < self._points[-1][0]:
            self._points.clear()
        if self._points and time_us - self._points[-1][0] < self.spacing_us:
            return
        self._points.append((time_us, p_enu_m))
        while time_us - self._points[0][0] > self.window_us:
            self._points.popleft()

    def points(self) -> list[Vec3]:
        return [p for _, p in self._points]

    def times_us(self) -> list[int]:
        return [t for t, _ in self._points]

    def __len__(self) -> int:
        return len(self._points)


@dataclass
class ViewState:
    """A sample and the two paths drawn from it."""

    sample: Sample = field(default_factory=Sample)
    flown: PathBuffer = field(default_factory=PathBuffer)
    desired: PathBuffer = field(default_factory=PathBuffer)

    def update_paths(self) -> None:
        s = self.sample
        if s.pose is not None and s.pose_time_us is not None:
            self.flown.add(s.pose_time_us, s.pose.p_enu_m)
        if s.desired is not None and s.desired_time_us is not None:
            self.desired.add(s.desired_time_us, s.desired.p_enu_m)


def _finite_list(values: Sequence[float] | None) -> list[float | None] | None:
    if values is None:
        return None
    return [float(v) if math.isfinite(v) else None for v in values]


def state_message(sample: Sample, source: str) -> dict[str, Any]:
    """The /vehicle/state JSON object of a sample (JSON has no NaN: unknown is null)."""
    t = sample.time_us
    return {
        "time_s": (t or 0) * 1e-6,
        "source": source,
        "mode": sample.mode,
        "armed": sample.armed,
        "rotor_speeds_rad_s": _finite_list(sample.rotor_speeds_rad_s),
        "tilts_rad": _finite_list(sample.tilts_rad),
        "position_enu_m": _finite_list(sample.pose.p_enu_m if sample.pose else None),
        "desired_position_enu_m": _finite_list(sample.desired.p_enu_m
                                               if sample.desired else None),
    }


def apply_message(sample: Sample, msg: Any) -> bool:
    """Update a sample from one MAVLink message (pymavlink object); True if it changed.

    ACTUATOR_OUTPUT_STATUS counts only with its first 12 outputs active (this project's
    packing: six speeds, six tilts); other autopilots' outputs are left out."""
    kind = msg.get_type()
    if kind == "LOCAL_POSITION_NED":
        q = sample.pose.q_enu_flu if sample.pose is not None else Q_IDENTITY
        sample.pose = Pose(ned_to_enu((msg.x, msg.y, msg.z)), q)
        sample.pose_time_us = int(msg.time_boot_ms) * 1000
    elif kind == "ATTITUDE_QUATERNION":
        p = sample.pose.p_enu_m if sample.pose is not None else (0.0, 0.0, 0.0)
        sample.pose = Pose(p, q_ned_frd_to_enu_flu((msg.q1, msg.q2, msg.q3, msg.q4)))
        if sample.pose_time_us is None:
            sample.pose_time_us = int(msg.time_boot_ms) * 1000
    elif kind == "POSITION_TARGET_LOCAL_NED":
        if msg.type_mask & 0b111:  # position ignored: a velocity or acceleration target
            return False
        q = sample.desired.q_enu_flu if sample.desired is not None else Q_IDENTITY
        sample.desired = Pose(ned_to_enu((msg.x, msg.y, msg.z)), q)
        sample.desired_time_us = int(msg.time_boot_ms) * 1000
    elif kind == "ATTITUDE_TARGET":
        if msg.type_mask & 0b1000_0000:  # attitude ignored
            return False
        p = sample.desired.p_enu_m if sample.desired is not None else (0.0, 0.0, 0.0)
        q1, q2, q3, q4 = (float(v) for v in msg.q)
        sample.desired = Pose(p, q_ned_frd_to_enu_flu((q1, q2, q3, q4)))
        if sample.desired_time_us is None:
            sample.desired_time_us = int(msg.time_boot_ms) * 1000
    elif kind == "ACTUATOR_OUTPUT_STATUS":
        if msg.active & 0xFFF != 0xFFF:
            return False
        values = [float(v) for v in msg.actuator[:12]]
        sample.rotor_speeds_rad_s = tuple(values[:6])
        sample.tilts_rad = tuple(values[6:12])
        sample.actuator_time_us = int(msg.time_usec)
    elif kind == "HEARTBEAT":
        from common.mavlink import MAV
        from gcs.vehicle_link import mode_name

        sample.mode = mode_name(msg.custom_mode, msg.autopilot, msg.type)
        sample.armed = bool(msg.base_mode & MAV.MAV_MODE_FLAG_SAFETY_ARMED)
    else:
        return False
    return True


# Replay -----------------------------------------------------------------------------------


def _cols(columns: Sequence[str], rows: np.ndarray, names: Sequence[str],
          what: str) -> np.ndarray:
    missing = [n for n in names if n not in columns]
    if missing:
        raise ViewError(f"{what}: no column {missing[0]}")
    return rows[:, [list(columns).index(n) for n in names]]


@dataclass
class ReplayLog:
    """The replayed samples: truth rows (time, pose, speeds, tilts) and onboard rows (time,
    desired pose, armed), ENU/FLU, each sorted by time."""

    truth_t_us: np.ndarray
    truth_p: np.ndarray
    truth_q: np.ndarray
    truth_rotors: np.ndarray
    truth_tilts: np.ndarray
    onboard_t_us: np.ndarray
    onboard_pd: np.ndarray
    onboard_qd: np.ndarray
    onboard_armed: np.ndarray | None

    @classmethod
    def from_rows(cls, truth_cols: Sequence[str], truth: np.ndarray,
                  onboard_cols: Sequence[str] | None = None,
                  onboard: np.ndarray | None = None) -> ReplayLog:
        truth = truth[np.isfinite(_cols(truth_cols, truth, ("time_us",), "dq_truth")[:, 0])]
        if onboard is None or onboard_cols is None:
            onboard_cols, onboard = ("time_us",), np.zeros((0, 1))
        onboard = onboard[np.isfinite(_cols(onboard_cols, onboard, ("time_us",),
                                            "dq_onboard")[:, 0])]
        truth = truth[np.argsort(_cols(truth_cols, truth, ("time_us",), "dq_truth")[:, 0],
                                 kind="stable")]
        ob_t = _cols(onboard_cols, onboard, ("time_us",), "dq_onboard")[:, 0]
        onboard, ob_t = onboard[np.argsort(ob_t, kind="stable")], np.sort(ob_t, kind="stable")
        armed = (_cols(onboard_cols, onboard, ("armed",), "dq_onboard")[:, 0]
                 if "armed" in onboard_cols else None)
        has_desired = len(onboard) > 0
        return cls(
            truth_t_us=_cols(truth_cols, truth, ("time_us",), "dq_truth")[:, 0].astype(np.int64),
            truth_p=_cols(truth_cols, truth, ("px", "py", "pz"), "dq_truth"),
            truth_q=_cols(truth_cols, truth, ("qw", "qx", "qy", "qz"), "dq_truth"),
            truth_rotors=_cols(truth_cols, truth, [f"rotor{i}" for i in range(6)], "dq_truth"),
            truth_tilts=_cols(truth_cols, truth, [f"tilt{i}" for i in range(6)], "dq_truth"),
            onboard_t_us=ob_t.astype(np.int64),
            onboard_pd=(_cols(onboard_cols, onboard, ("pdx", "pdy", "pdz"), "dq_onboard")
                        if has_desired else np.zeros((0, 3))),
            onboard_qd=(_cols(onboard_cols, onboard, ("qdw", "qdx", "qdy", "qdz"), "dq_onboard")
                        if has_desired else np.zeros((0, 4))),
            onboard_armed=armed)

    @property
    def span_us(self) -> tuple[int, int]:
        if len(self.truth_t_us) == 0:
            raise ViewError("dq_truth holds no rows")
        return int(self.truth_t_us[0]), int(self.truth_t_us[-1])

    def sample_at(self, t_us: int) -> Sample:
        """The sample as it stood at `t_us`: the last truth and onboard rows at or before."""
        s = Sample()
        i = int(np.searchsorted(self.truth_t_us, t_us, side="right")) - 1
        if i >= 0:
            s.pose = Pose(_vec3(self.truth_p[i]), _quat(self.truth_q[i]))
            s.pose_time_us = int(self.truth_t_us[i])
            s.rotor_speeds_rad_s = tuple(float(v) for v in self.truth_rotors[i])
            s.tilts_rad = tuple(float(v) for v in self.truth_tilts[i])
            s.actuator_time_us = s.pose_time_us
        j = int(np.searchsorted(self.onboard_t_us, t_us, side="right")) - 1
        if j >= 0:
            pd, qd = self.onboard_pd[j], self.onboard_qd[j]
            if np.all(np.isfinite(pd)) and np.all(np.isfinite(qd)):
                s.desired = Pose(_vec3(pd), _quat(qd))
                s.desired_time_us = int(self.onboard_t_us[j])
            if self.onboard_armed is not None:
                s.armed = bool(self.onboard_armed[j] > 0.5)
        return s


def _vec3(a: np.ndarray) -> Vec3:
    return (float(a[0]), float(a[1]), float(a[2]))


def _quat(a: np.ndarray) -> Quat:
    return (float(a[0]), float(a[1]), float(a[2]), float(a[3]))


def replay_ticks(t_first_us: int, t_last_us: int, hz: int = BASE_HZ) -> Iterator[int]:
    """Publishing instants of a replay: every 1/hz s of the timeline, first to last row."""
    step = 1_000_000 // hz
    t = t_first_us
    while t <= t_last_us:
        yield t
        t += step


def due_topics(tick: int) -> list[str]:
    """The topics published at tick number `tick` of the BASE_HZ tick."""
    return [topic for topic, hz in RATES_HZ.items() if tick % (BASE_HZ // hz) == 0]


# ---------------------------------------------------------------------------------------
# Foxglove messages (pure constructors)
# ---------------------------------------------------------------------------------------


def _fx_time(time_us: int) -> Any:
    from foxglove.messages import Timestamp

    return Timestamp(time_us // 1_000_000, (time_us % 1_000_000) * 1000)


def _fx_pose(p: Vec3 = (0.0, 0.0, 0.0), q: Quat = Q_IDENTITY) -> Any:
    from foxglove.messages import Pose as FxPose
    from foxglove.messages import Quaternion, Vector3

    return FxPose(position=Vector3(x=p[0], y=p[1], z=p[2]),
                  orientation=Quaternion(w=q[0], x=q[1], y=q[2], z=q[3]))


def frame_transforms(edges: Sequence[Transform]) -> FrameTransforms:
    from foxglove.messages import FrameTransform, FrameTransforms, Quaternion, Vector3

    return FrameTransforms(transforms=[
        FrameTransform(timestamp=_fx_time(e.time_us), parent_frame_id=e.parent,
                       child_frame_id=e.child,
                       translation=Vector3(x=e.translation[0], y=e.translation[1],
                                           z=e.translation[2]),
                       rotation=Quaternion(w=e.rotation[0], x=e.rotation[1], y=e.rotation[2],
                                           z=e.rotation[3]))
        for e in edges])


def path_scene(entity_id: str, points: Sequence[Vec3], rgba: tuple[float, float, float, float],
               time_us: int) -> SceneUpdate:
    """A path as a line strip in `world`."""
    from foxglove.messages import (
        Color,
        LinePrimitive,
        LinePrimitiveLineType,
        Point3,
        SceneEntity,
        SceneUpdate,
    )

    line = LinePrimitive(type=LinePrimitiveLineType.LineStrip, pose=_fx_pose(), thickness=0.03,
                         points=[Point3(x=p[0], y=p[1], z=p[2]) for p in points],
                         color=Color(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3]))
    return SceneUpdate(entities=[SceneEntity(timestamp=_fx_time(time_us), frame_id="world",
                                             id=entity_id, lines=[line])])


_Q_X_TO_Z: Quat = (math.sqrt(0.5), 0.0, -math.sqrt(0.5), 0.0)  # arrows point along x


def airframe_scene(vehicle: VehicleConfig, time_us: int) -> SceneUpdate:
    """Body, arms and rotor disks (frame-locked to base_link and rotor_i), and a ghost body
    in `desired`; sized from the vehicle's arm length."""
    from foxglove.messages import (
        ArrowPrimitive,
        Color,
        CubePrimitive,
        CylinderPrimitive,
        LinePrimitive,
        LinePrimitiveLineType,
        Point3,
        SceneEntity,
        SceneUpdate,
        Vector3,
    )

    ts = _fx_time(time_us)
    arm = vehicle.arm_length_m
    body_size = Vector3(x=0.6 * arm, y=0.6 * arm, z=0.25 * arm)
    grey = Color(r=0.6, g=0.6, b=0.65, a=1.0)
    forward = ArrowPrimitive(pose=_fx_pose(), shaft_length=0.6 * arm, shaft_diameter=0.03 * arm,
                             head_length=0.15 * arm, head_diameter=0.08 * arm,
                             color=Color(r=1.0, g=0.2, b=0.2, a=1.0))
    arms = LinePrimitive(type=LinePrimitiveLineType.LineList, pose=_fx_pose(),
                         thickness=0.06 * arm, color=grey,
                         points=[Point3(x=c, y=d, z=e) for fr in rotor_frames(vehicle)
                                 for (c, d, e) in ((0.0, 0.0, 0.0), fr.r_flu_m)])
    entities = [
        SceneEntity(timestamp=ts, frame_id="base_link", id="body", frame_locked=True,
                    cubes=[CubePrimitive(pose=_fx_pose(), size=body_size, color=grey)],
                    arrows=[forward], lines=[arms]),
        SceneEntity(timestamp=ts, frame_id="desired", id="desired", frame_locked=True,
                    cubes=[CubePrimitive(pose=_fx_pose(), size=body_size,
                                         color=Color(r=0.2, g=0.9, b=0.3, a=0.35))],
                    arrows=[ArrowPrimitive(pose=_fx_pose(), shaft_length=0.6 * arm,
                                           shaft_diameter=0.03 * arm, head_length=0.15 * arm,
                                           head_diameter=0.08 * arm,
                                           color=Color(r=0.2, g=0.9, b=0.3, a=0.5))]),
    ]
    for i, fr in enumerate(rotor_frames(vehicle)):
        ccw = fr.spin > 0
        disk = CylinderPrimitive(pose=_fx_pose(), size=Vector3(x=0.8 * arm, y=0.8 * arm,
                                                               z=0.03 * arm),
                                 color=Color(r=0.2 if ccw else 0.9, g=0.4, b=0.9 if ccw else 0.2,
                                             a=0.6))
        thrust = ArrowPrimitive(pose=_fx_pose(q=_Q_X_TO_Z), shaft_length=0.4 * arm,
                                shaft_diameter=0.02 * arm, head_length=0.1 * arm,
                                head_diameter=0.06 * arm, color=Color(r=1.0, g=0.8, b=0.1, a=1))
        entities.append(SceneEntity(timestamp=ts, frame_id=f"rotor_{i}", id=f"rotor_{i}",
                                    frame_locked=True, cylinders=[disk], arrows=[thrust]))
    return SceneUpdate(entities=entities)


# ---------------------------------------------------------------------------------------
# I/O: channels, server, MCAP, the live and replay loops
# ---------------------------------------------------------------------------------------


class Publisher:
    """The five channels on one Foxglove context (the server and the MCAP writer are its
    sinks); `tick` publishes the channels due at a tick of the BASE_HZ clock."""

    def __init__(self, context: foxglove.Context, vehicle: VehicleConfig, source: str) -> None:
        import foxglove
        from foxglove.channels import FrameTransformsChannel, SceneUpdateChannel

        def meta(topic: str) -> dict[str, str]:
            return {"rate_hz": str(RATES_HZ[topic])}

        self.vehicle = vehicle
        self.mounts = arm_mounts(vehicle)
        self.source = source
        self.tf = FrameTransformsChannel("/tf", metadata=meta("/tf"), context=context)
        self.state = foxglove.Channel("/vehicle/state", schema=STATE_SCHEMA,
                                      metadata=meta("/vehicle/state"), context=context)
        self.flown = SceneUpdateChannel("/path/flown", metadata=meta("/path/flown"),
                                        context=context)
        self.desired = SceneUpdateChannel("/path/desired", metadata=meta("/path/desired"),
                                          context=context)
        self.airframe = SceneUpdateChannel("/airframe", metadata=meta("/airframe"),
                                           context=context)

    def tick(self, view: ViewState, tick: int) -> bool:
        """Publish what is due; nothing before the vehicle's time is known."""
        t_us = view.sample.time_us
        if t_us is None:
            return False
        log_time = t_us * 1000
        for topic in due_topics(tick):
            if topic == "/tf":
                self.tf.log(frame_transforms(transforms(view.sample, self.mounts)),
                            log_time=log_time)
            elif topic == "/vehicle/state":
                self.state.log(state_message(view.sample, self.source), log_time=log_time)
            elif topic == "/path/flown":
                self.flown.log(path_scene("path/flown", view.flown.points(),
                                          (1.0, 0.55, 0.1, 1.0), t_us), log_time=log_time)
            elif topic == "/path/desired":
                self.desired.log(path_scene("path/desired", view.desired.points(),
                                            (0.2, 0.9, 0.3, 0.8), t_us), log_time=log_time)
            elif topic == "/airframe":
                self.airframe.log(airframe_scene(self.vehicle, t_us), log_time=log_time)
        return True


class _Stop:
    """SIGINT and SIGTERM set a flag (restored on exit) so that the loops end cleanly."""

    def __init__(self) -> None:
        self.event = threading.Event()
        self._old: dict[int, Any] = {}

    def __enter__(self) -> threading.Event:
        def handler(signum: int, frame: FrameType | None) -> None:
            self.event.set()

        for sig in (signal.SIGINT, signal.SIGTERM):
            self._old[sig] = signal.signal(sig, handler)
        return self.event

    def __exit__(self, *exc: object) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)


def _load_geometry(path: Path | None) -> VehicleConfig:
    try:
        return load_vehicle(path or DEFAULT_VEHICLE)
    except ConfigError as exc:
        raise ViewError(str(exc)) from None


def replay_vehicle_path(run_dir: Path) -> Path:
    """The vehicle file a run folder's scenario names (looked up among config/vehicles by
    name, the copied scenario's relative path no longer resolving), else the default."""
    try:
        name = Path(str(tomllib.loads((run_dir / "scenario.toml").read_text())["vehicle"])).name
    except (OSError, KeyError, tomllib.TOMLDecodeError):
        return DEFAULT_VEHICLE
    candidate = DEFAULT_VEHICLE.parent / name
    return candidate if candidate.is_file() else DEFAULT_VEHICLE


def load_replay(run_dir: Path) -> ReplayLog:
    """The run folder's truth.ulg (required) and onboard.ulg (optional) as a ReplayLog."""
    if not run_dir.is_dir():
        raise ViewError(f"{run_dir} is not a folder")
    truth_path, onboard_path = run_dir / "truth.ulg", run_dir / "onboard.ulg"
    if not truth_path.is_file():
        raise ViewError(f"{run_dir} has no truth.ulg (not a run folder with ULog logs)")
    try:
        from common import ulog
    except ImportError:
        raise ViewError("replay needs common/ulog.py (ULog reader)") from None
    try:
        tc, truth = ulog.read_topic(truth_path, "dq_truth")
        oc: tuple[str, ...] | None = None
        onboard = None
        if onboard_path.is_file():
            oc, onboard = ulog.read_topic(onboard_path, "dq_onboard")
    except (ulog.ULogError, OSError, ValueError) as exc:
        raise ViewError(str(exc)) from None
    log = ReplayLog.from_rows(tc, truth, oc, onboard)
    log.span_us  # noqa: B018  (refuses an empty log now)
    return log


class Outputs:
    """The Foxglove context with its sinks: the WebSocket server on 127.0.0.1 and the
    optional MCAP writer; closed (MCAP finalised) by `close`."""

    def __init__(self, port: int, mcap: Path | None) -> None:
        try:
            import foxglove
        except ImportError:
            raise ViewError("needs the foxglove-sdk package (pip install foxglove-sdk)") from None
        if mcap is not None and mcap.exists():
            raise ViewError(f"{mcap} exists; not overwriting a recording")
        self.context = foxglove.Context()
        self.mcap_path = mcap
        try:
            self.server = foxglove.start_server(name="dqflight gcs view", host=HOST, port=port,
                                                context=self.context)
        except (RuntimeError, OSError, ValueError, OverflowError) as exc:
            raise ViewError(f"cannot serve on {HOST}:{port}: "
                            f"{str(exc).removeprefix('FoxgloveError: ')}") from None
        self.writer = None
        if mcap is not None:
            try:
                self.writer = foxglove.open_mcap(mcap, context=self.context)
            except OSError as exc:
                self.server.stop()
                raise ViewError(f"{mcap}: {exc.strerror or exc}") from None

    @property
    def url(self) -> str:
        return f"ws://{HOST}:{self.server.port}"

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()
            self.writer = None
        self.server.stop()


def _announce(outputs: Outputs) -> None:
    print(f"gcs view: {outputs.url}", flush=True)
    print("gcs view: open it in Foxglove or Lichtblick (Open connection > Foxglove WebSocket); "
          "display frame: world", flush=True)
    if outputs.mcap_path is not None:
        print(f"gcs view: recording to {outputs.mcap_path}", flush=True)


def run_live(session: Session, publisher: Publisher, stop: threading.Event,
             duration_s: float | None = None) -> None:
    """Take the vehicle's messages and publish on a wall-clock tick of BASE_HZ until `stop`
    (or `duration_s`); a late tick never makes a burst."""
    view = ViewState()
    period = 1.0 / BASE_HZ
    start = time.monotonic()
    next_tick = start
    tick = 0
    while not stop.is_set():
        now = time.monotonic()
        if duration_s is not None and now - start >= duration_s:
            return
        if now >= next_tick:
            if publisher.tick(view, tick):
                tick += 1
            next_tick = max(next_tick + period, now)
            continue
        msg = session.recv(None, timeout=min(0.05, next_tick - now))
        if msg is None or msg.get_type() == "BAD_DATA":
            continue
        if (msg.get_srcSystem() != session.target_system
                or msg.get_srcComponent() != session.target_component):
            continue
        t_before = view.sample.time_us
        if apply_message(view.sample, msg):
            t_after = view.sample.time_us
            if t_before is not None and t_after is not None and t_after < t_before:
                view.flown, view.desired = PathBuffer(), PathBuffer()  # a new flight
            view.update_paths()


def run_replay(log: ReplayLog, publisher: Publisher, speed: float,
               stop: threading.Event) -> bool:
    """Publish the log on its timeline at `speed` x real time (0: at once); False if
    stopped before the end."""
    first, last = log.span_us
    view = ViewState()
    wall0 = time.monotonic()
    for tick, t_us in enumerate(replay_ticks(first, last)):
        if speed > 0.0:
            delay = wall0 + (t_us - first) * 1e-6 / speed - time.monotonic()
            if delay > 0.0 and stop.wait(delay):
                return False
        if stop.is_set():
            return False
        view.sample = log.sample_at(t_us)
        view.update_paths()
        publisher.tick(view, tick)
    return True


def _wait_vehicle(session: Session, timeout: float, system_id: int | None,
                  stop: threading.Event) -> bool:
    """Session.wait_vehicle in short slices, so that Ctrl-C ends the wait at once."""
    from gcs.session import GcsError

    deadline = time.monotonic() + timeout
    while not stop.is_set():
        try:
            session.wait_vehicle(timeout=min(0.5, max(0.05, deadline - time.monotonic())),
                                 system_id=system_id)
            return True
        except GcsError:
            if time.monotonic() >= deadline:
                raise GcsError(f"no vehicle heartbeat within {timeout:g} s") from None
    return False


def view_live(connect: str, *, port: int = DEFAULT_PORT, mcap: Path | None = None,
              vehicle_file: Path | None = None, system_id: int | None = None,
              wait_s: float = 10.0, signing_key: bytes | None = None,
              duration_s: float | None = None) -> int:
    """`gcs view [--connect URL]`: serve the vehicle's telemetry until Ctrl-C or SIGTERM.
    Raises ViewError (bad input), LinkError (bad URL), GcsError (no vehicle)."""
    from gcs.session import Session

    vehicle = _load_geometry(vehicle_file)
    outputs = Outputs(port, mcap)
    try:
        with _Stop() as stop:
            publisher = Publisher(outputs.context, vehicle, "live")
            try:
                session = Session(connect, vehicle=system_id or 0, signing_key=signing_key)
            except OSError as exc:  # e.g. a host name that does not resolve
                raise ViewError(f"cannot open {connect}: {exc.strerror or exc}") from None
            try:
                _announce(outputs)
                if _wait_vehicle(session, wait_s, system_id, stop):
                    print(f"gcs view: vehicle {session.target_system} on {connect}",
                          flush=True)
                    run_live(session, publisher, stop, duration_s)
            finally:
                session.close()
    finally:
        outputs.close()
    if mcap is not None:
        print(f"gcs view: wrote {mcap}", flush=True)
    return 0


def view_replay(run_dir: Path, *, port: int = DEFAULT_PORT, mcap: Path | None = None,
                speed: float = 1.0, vehicle_file: Path | None = None) -> int:
    """`gcs view RUN_DIR`: replay the run's logs at `speed` x real time, then exit."""
    if not (speed >= 0.0 and math.isfinite(speed)):
        raise ViewError(f"--speed must be a finite number >= 0, got {speed}")
    log = load_replay(run_dir)
    vehicle = _load_geometry(vehicle_file or replay_vehicle_path(run_dir))
    outputs = Outputs(port, mcap)
    try:
        with _Stop() as stop:
            publisher = Publisher(outputs.context, vehicle, "replay")
            _announce(outputs)
            finished = run_replay(log, publisher, speed, stop)
    finally:
        outputs.close()
    first, last = log.span_us
    print(f"gcs view: replayed {(last - first) * 1e-6:.2f} s of {run_dir}"
          + ("" if finished else " (stopped)"), flush=True)
    if mcap is not None:
        print(f"gcs view: wrote {mcap}", flush=True)
    return 0
