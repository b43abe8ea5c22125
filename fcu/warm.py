"""Every planner's kernels loaded before the loop flies (`common.warm_ups.warm_up`): the first
mission, take-off, OFFBOARD anchor, HOLD brake and POSCTL fit of a flight then cost what
every later one costs. numba compiles (or loads from its cache) a kernel at its first call
with each argument type; left to the first use, that was 2-12 ms per kernel inside a control
step in real time (the first step armed loaded five quaternion kernels: 9 ms), and 100 ms
in the worker's first job (`fcu.edge.work_process`), which then came after its time.

`warm(limits)` runs in the FCU's process before its loop and, in real time, as the worker's
first job."""

from __future__ import annotations

from common import quaternion
from common.config.scenario import VehicleConfig
from common.warm_ups import warm_up
from fcu.envelope.feasibility import envelope
from fcu.mission.limits import MissionLimits
from fcu.mission.start import warm as warm_mission
from fcu.modes import manual, offboard
from fcu.reference import approach
from fcu.stages import Reference

_MOVING = Reference((0.0, 0.0, 1.0), (1.0, 0.0, 0.0, 0.0), (1.0, 0.5, 0.0), (0.5, 0.0, 0.0),
                    (0.0, 0.0, 0.2), (0.0, 0.0, 0.0))


def _quaternions() -> None:
    q, v = (1.0, 0.0, 0.0, 0.0), (0.1, 0.2, 0.3)
    quaternion.cross(v, v)
    quaternion.norm3(v)
    quaternion.q_angle(quaternion.q_normalize(quaternion.q_mul(q, quaternion.q_conj(q))))
    quaternion.q_log(quaternion.q_exp(v))
    quaternion.q_rotate(q, v)
    quaternion.q_rotate_inv(q, v)
    manual.yawed(q, 0.5)


def _planners(vehicle: VehicleConfig | None) -> None:
    env = envelope(vehicle) if vehicle is not None else None
    lim = offboard.limits(manual.StickSettings())
    offboard.brake_ahead(offboard.coast(0, _MOVING), 10_000, lim, env)
    offboard.start_ahead(offboard.coast(0, _MOVING), 10_000, lim, env)
    manual.fit_envelope(manual.StickSettings(), vehicle, (1.0, 0.0, 0.0, 0.0))


def warm(limits: MissionLimits) -> None:
    """Load the kernels of the mission planner, the approach (OFFBOARD's and HOLD's plans
    from a moving reference) and POSCTL's envelope fit, with the vehicle of `limits`."""
    warm_up("common.quaternion", _quaternions)
    approach.warm()
    warm_mission(limits)
    warm_up("fcu.warm", lambda: _planners(limits.vehicle))
