"""Foxglove messages of the view (pure constructors): the frame tree as FrameTransforms,
paths as line strips in `world`, and the airframe as a SceneUpdate."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from common.config.scenario import VehicleConfig
from common.geometry import rotor_frames
from common.quaternion import Q_IDENTITY, Quat, Vec3
from gcs.view.sample import Transform

if TYPE_CHECKING:
    from foxglove.messages import FrameTransforms, SceneUpdate


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

