"""`gcs view`'s pure model: poses in ENU/FLU, the arm mountings and the frame tree
(`base_link` -> `arm_i` turned by the tilt alpha_i about the arm axis), the latest sample,
the bounded paths and the /vehicle/state message."""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

from common.config.scenario import VehicleConfig
from common.frames import ned_to_enu, q_ned_frd_to_enu_flu
from common.geometry import rotor_frames
from common.quaternion import Q_IDENTITY, Quat, Vec3, q_exp, q_mul
from gcs.view.settings import PATH_SPACING_US, PATH_WINDOW_US


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

