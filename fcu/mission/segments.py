"""Planned segments: one mission item each, sampled at tau = t - t0.

A move is the minimum-jerk quintic of `fcu.reference.trajectory` in position and along the shortest
rotation in attitude, then a hold; a figure is `fcu.reference.trajectory.FigureInfinity`. Both
sample one instant (`sample`) or, for the envelope check, a whole normalised path at once (`path`;
both also its allocations, `unit_allocations`, a move's straight from its parameters,
keeping in the envelope what other paths share with it, and the bytes of what that path
depends on, `path_key`, by which `fcu.envelope.feasibility` shares the scaling of equal paths).
"""

from __future__ import annotations

import math
import struct
from typing import Any, NamedTuple

import numpy as np

from common.frames import q_ned_frd_to_enu_flu
from common.jit import njit
from common.quaternion import q_exp_many
from fcu.control.dualquat import Quat, Vec3, norm3, q_conj, q_exp, q_log, q_mul
from fcu.envelope.feasibility import (
    Envelope,
    TimeScaling,
    at_rest,
    figure_instants,
    move_instants,
    nominal_wrench_kernel,
)
from fcu.reference.trajectory import (
    FigureInfinity,
    FigureShape,
    figure_shape,
    quintic,
    quintic_poly,
)
from fcu.stages import Reference, pose_ref

ZERO: Vec3 = (0.0, 0.0, 0.0)


def level_attitude(yaw_ned_deg: float) -> Quat:
    """Level attitude (ENU/FLU) heading at a NED yaw in degrees."""
    return q_ned_frd_to_enu_flu(q_exp((0.0, 0.0, math.radians(yaw_ned_deg))))


_NO_Q = np.zeros(0)


def _floats(*parts: float) -> bool:
    """Every part a float (numpy's float64 too): a loop, faster than all() of a generator."""
    for c in parts:
        if not isinstance(c, float):
            return False
    return True


@njit
def quintic_rows(sigma: np.ndarray) -> np.ndarray:
    """`fcu.reference.trajectory.quintic_poly` at each sigma (its expressions, so its values): rows
    s, s', s''."""
    out = np.empty((3, sigma.shape[0]))
    for i in range(sigma.shape[0]):
        s = sigma[i]
        s2 = s * s
        out[0, i] = s2 * s * (10.0 - 15.0 * s + 6.0 * s2)
        out[1, i] = 30.0 * s2 * (1.0 - 2.0 * s + s2)
        out[2, i] = 60.0 * s * (1.0 - 3.0 * s + 2.0 * s2)
    return out


@njit
def move_wrenches(m: float, g: float, inertia: Vec3, q0: Quat, dp: Vec3, quintic: np.ndarray,
                  turned: np.ndarray, torque: np.ndarray, moving: np.ndarray) -> None:
    """The nominal wrenches (`fcu.envelope.feasibility.Envelope.wrenches`) of a move's 1 s path
    (`Move.path`) at the instants of `quintic` (`quintic_rows`) into `moving`: its attitude
    q0 where it keeps it (`turned` empty), else each instant's attitude q0 exp(s phi) and the
    torque of its rates from `turned` and `torque` (`rest_wrenches`, the same values)."""
    zero = (0.0, 0.0, 0.0)
    turns = turned.shape[0] > 0
    for i in range(quintic.shape[1]):
        dds = quintic[2, i]
        a = (dp[0] * dds / 1.0, dp[1] * dds / 1.0, dp[2] * dds / 1.0)
        if turns:
            q = (turned[i, 0], turned[i, 1], turned[i, 2], turned[i, 3])
            f, _ = nominal_wrench_kernel(m, g, inertia, q, a, zero, zero)
            moving[i, 0], moving[i, 1], moving[i, 2] = f
            moving[i, 3], moving[i, 4], moving[i, 5] = torque[i, 0], torque[i, 1], torque[i, 2]
        else:
            f, t = nominal_wrench_kernel(m, g, inertia, q0, a, zero, zero)
            moving[i, 0], moving[i, 1], moving[i, 2] = f
            moving[i, 3], moving[i, 4], moving[i, 5] = t


@njit
def rest_wrenches(m: float, g: float, inertia: Vec3, q0: Quat, phi: Vec3, quintic: np.ndarray,
                  qw: np.ndarray, qx: np.ndarray, qy: np.ndarray, qz: np.ndarray,
                  hover: np.ndarray, turned: np.ndarray, torque: np.ndarray) -> None:
    """The nominal wrenches of a move's poses at rest into `hover`: one row where it keeps
    its attitude q0 (qw empty), else a row per instant at q0 exp(s phi) from exp(s phi) =
    (qw, qx, qy, qz), that attitude into `turned` (a row per instant) and the torque of the
    rates s' phi, s'' phi (`quintic`'s rows) into `torque`: what `move_wrenches` shares."""
    zero = (0.0, 0.0, 0.0)
    if qw.shape[0] == 0:
        f, t = nominal_wrench_kernel(m, g, inertia, q0, zero, zero, zero)
        hover[0, 0], hover[0, 1], hover[0, 2] = f
        hover[0, 3], hover[0, 4], hover[0, 5] = t
    for i in range(qw.shape[0]):
        q = q_mul(q0, (qw[i], qx[i], qy[i], qz[i]))
        f, t = nominal_wrench_kernel(m, g, inertia, q, zero, zero, zero)
        hover[i, 0], hover[i, 1], hover[i, 2] = f
        hover[i, 3], hover[i, 4], hover[i, 5] = t
        turned[i, 0], turned[i, 1], turned[i, 2], turned[i, 3] = q
        ds, dds = quintic[1, i], quintic[2, i]
        w = (phi[0] * ds / 1.0, phi[1] * ds / 1.0, phi[2] * ds / 1.0)
        wd = (phi[0] * dds / 1.0, phi[1] * dds / 1.0, phi[2] * dds / 1.0)
        _, t = nominal_wrench_kernel(m, g, inertia, q, zero, w, wd)
        torque[i, 0], torque[i, 1], torque[i, 2] = t


@njit
def figure_wrenches(m: float, g: float, inertia: Vec3, q0: Quat, turned: bool, nb: Vec3,
                    turn_w: np.ndarray,
                    turn_x: np.ndarray, turn_y: np.ndarray, turn_z: np.ndarray,
                    shape: np.ndarray, unit: np.ndarray, rest: np.ndarray) -> None:
    """The nominal wrenches of a figure's 1 s path (`Figure.path`) into `unit` and of its
    poses at rest into `rest`, a row per instant: its attitude exp(T n) q0 from exp(T n) =
    (turn_w, turn_x, turn_y, turn_z) (not `turned`: exp(T n) itself), its body rate T' nb and
    its derivative T'' nb (`shape`: rows T', T'', then the acceleration's three)."""
    zero = (0.0, 0.0, 0.0)
    for i in range(turn_w.shape[0]):
        q = (turn_w[i], turn_x[i], turn_y[i], turn_z[i])
        if turned:
            q = q_mul(q, q0)
        dT, ddT = shape[0, i], shape[1, i]
        w = (dT * nb[0], dT * nb[1], dT * nb[2])
        wd = (ddT * nb[0], ddT * nb[1], ddT * nb[2])
        f, t = nominal_wrench_kernel(m, g, inertia, q, (shape[2, i], shape[3, i], shape[4, i]),
                                     w, wd)
        unit[i, 0], unit[i, 1], unit[i, 2] = f
        unit[i, 3], unit[i, 4], unit[i, 5] = t
        f, t = nominal_wrench_kernel(m, g, inertia, q, zero, zero, zero)
        rest[i, 0], rest[i, 1], rest[i, 2] = f
        rest[i, 3], rest[i, 4], rest[i, 5] = t


_H = math.sqrt(0.5)


@njit
def keyframe_turn(q0: Quat, rx: float, ry: float, rz: float) -> tuple[Vec3, bool, Quat]:
    """A pose keyframe's turn from q0 to the NED/FRD attitude exp((rx, ry, rz)): (phi, the
    shortest rotation; whether it turns, |phi| > 0; its end q0 exp(phi), or q0), as
    `fcu.mission.planning.plan_item` and `Move` make them from `q_exp`,
    `common.frames.q_ned_frd_to_enu_flu` (its operations written out, its non-finite branch
    through `q_mul`), `q_log` and `q_mul`, in one compiled call."""
    q = q_exp((rx, ry, rz))
    w, x, y, z = q[0], q[1], q[2], q[3]
    if not math.isfinite(w + x + y + z):
        r = q_mul(q_mul((0.0, _H, _H, 0.0), q), (0.0, 1.0, 0.0, 0.0))
        q1 = r if r[0] >= 0.0 else (-r[0], -r[1], -r[2], -r[3])
    else:
        h = _H
        aw = 0.0 * w - h * x - h * y - 0.0 * z
        ax = 0.0 * x + h * w + h * z - 0.0 * y
        ay = 0.0 * y - h * z + h * w + 0.0 * x
        az = 0.0 * z + h * y - h * x + 0.0 * w
        rw = aw * 0.0 - ax * 1.0 - ay * 0.0 - az * 0.0
        rx_ = aw * 1.0 + ax * 0.0 + ay * 0.0 - az * 0.0
        ry_ = aw * 0.0 - ax * 0.0 + ay * 0.0 + az * 1.0
        rz_ = aw * 0.0 + ax * 0.0 - ay * 1.0 + az * 0.0
        q1 = (rw, rx_, ry_, rz_) if rw >= 0.0 else (-rw, -rx_, -ry_, -rz_)
    phi = q_log(q_mul(q_conj(q0), q1))
    if norm3(phi) > 0.0:
        return phi, True, q_mul(q0, q_exp(phi))
    return phi, False, q0


class MoveRest(NamedTuple):
    """What a move's path at its instants shares with every move of the same q0 and phi
    (`Move.unit_allocations`): the quintic's rows there (`quintic_rows`), the attitudes
    q0 exp(s phi) and the torques of the rates there (`rest_wrenches`; empty where it keeps
    its attitude) and the allocation of its poses at rest (one row where it keeps its
    attitude)."""

    quintic: np.ndarray
    turned: np.ndarray
    torque: np.ndarray
    hover: np.ndarray


class Segment:
    """Base: planned start/end time, start and end pose; `duration` is the part that moves
    (the rest, if any, holds the end pose)."""

    seq: int
    t0: float
    t1: float
    duration: float
    p_end: Vec3
    q_end: Quat
    end_ref: Reference
    scaling: TimeScaling | None = None  # set where the envelope has been evaluated

    def sample(self, tau: float) -> Reference:  # pragma: no cover - overridden
        raise NotImplementedError

    def starting(self, t0: float) -> None:  # pragma: no cover - overridden
        """Start at t0 instead (the same segment and timing)."""
        raise NotImplementedError

    def path(self, sigma: np.ndarray) -> Reference:  # pragma: no cover - overridden
        """The moving part flown in 1 s, at normalised times sigma (arrays)."""
        raise NotImplementedError

    def instants(self) -> np.ndarray:  # pragma: no cover - overridden
        """Normalised times at which the envelope is checked."""
        raise NotImplementedError


class Move(Segment):
    """Quintic move p0 -> p0 + dp, q0 -> q0 exp(phi) in `travel` s, then hold `hold` s."""

    def __init__(self, seq: int, t0: float, p0: Vec3, dp: Vec3, q0: Quat, phi: Vec3 | None,
                 travel: float, hold: float, q_end: Quat | None = None) -> None:
        """`q_end`: q0 exp(phi) where the caller has it (`keyframe_turn`)."""
        self.seq, self.t0 = seq, t0
        self.p0, self.dp, self.q0, self.phi = p0, dp, q0, phi
        self.travel = self.duration = travel
        self.hold = hold
        self.t1 = t0 + travel + hold
        self.p_end = (p0[0] + dp[0], p0[1] + dp[1], p0[2] + dp[2])
        if q_end is None:
            q_end = q0 if phi is None else q_mul(q0, q_exp(phi))
        self.q_end = q_end
        self.end_ref = pose_ref(self.p_end, self.q_end)

    def retimed(self, travel: float) -> Move:
        return Move(self.seq, self.t0, self.p0, self.dp, self.q0, self.phi, travel, self.hold)

    def starting(self, t0: float) -> None:
        """Start at t0 instead (the same move and timing): planned before the durations of
        the items before it were known."""
        self.t0 = t0
        self.t1 = t0 + self.travel + self.hold

    def _at(self, s: Any, ds: Any, dds: Any, d: float, many: bool = False) -> Reference:
        p0, dp = self.p0, self.dp
        p = (p0[0] + s * dp[0], p0[1] + s * dp[1], p0[2] + s * dp[2])
        # Same association as FigureEight's rise: h * s' / T, h * s'' / (T T).
        v = (dp[0] * ds / d, dp[1] * ds / d, dp[2] * ds / d)
        d2 = d * d
        a = (dp[0] * dds / d2, dp[1] * dds / d2, dp[2] * dds / d2)
        phi = self.phi
        if phi is None:
            return Reference(p, self.q0, v, a, ZERO, ZERO)
        # q = q0 exp(s phi): body rate s' phi (phi commutes with exp(s phi)), derivative s'' phi.
        rot = (s * phi[0], s * phi[1], s * phi[2])
        q = q_mul(self.q0, q_exp_many(*rot) if many else q_exp(rot))
        w = (phi[0] * ds / d, phi[1] * ds / d, phi[2] * ds / d)
        wd = (phi[0] * dds / d2, phi[1] * dds / d2, phi[2] * dds / d2)
        return Reference(p, q, v, a, w, wd)

    def sample(self, tau: float) -> Reference:
        d = self.travel
        if tau >= d:
            return self.end_ref
        return self._at(*quintic(tau / d), d)

    def path(self, sigma: np.ndarray) -> Reference:
        return self._at(*quintic_poly(sigma), 1.0, many=True)

    def path_key(self) -> bytes:
        """What `path` and `instants` depend on (dp, q0, phi), as bytes."""
        phi = self.phi
        return struct.pack("<?10d", _floats(*self.q0), *self.dp, *self.q0,
                           *(phi if phi is not None else (math.nan,) * 3)) + \
            (b"t" if phi is not None else b"")

    def unit_allocations(self, env: Envelope, sigma: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray] | None:
        """The allocations of `path(sigma)` and of its poses at rest, as `Envelope.omega_sq`
        makes them (`move_wrenches`; None: through `path`). What depends on q0 and phi alone
        (`MoveRest`: its instants follow from phi) is kept in the envelope for moves that
        differ in dp only (`Envelope.kept`)."""
        if not _floats(*self.q0):
            return None  # `wrenches` takes such an attitude for arrays
        q0 = (float(self.q0[0]), float(self.q0[1]), float(self.q0[2]), float(self.q0[3]))
        dp = (float(self.dp[0]), float(self.dp[1]), float(self.dp[2]))
        rest = self.rest(env, sigma)
        vehicle = env.vehicle
        moving = np.empty((len(sigma), 6))
        move_wrenches(vehicle.mass_kg, vehicle.gravity_m_s2, vehicle.inertia_diag_kg_m2, q0,
                      dp, rest.quintic, rest.turned, rest.torque, moving)
        return env.allocate(moving), rest.hover

    def rest(self, env: Envelope, sigma: np.ndarray) -> MoveRest:
        """The `MoveRest` of this move's path at sigma, kept in the envelope (`Envelope.kept`)
        for the moves of the same q0 and phi (a float q0)."""
        q0 = self.q0
        phi = self.phi
        key = b"move rest" + struct.pack("<q4d", len(sigma), *q0) + (
            struct.pack("<3d", *phi) if phi is not None else b"")
        out: MoveRest = env.kept(key, len(sigma), lambda: self._rest(env, sigma))
        return out

    def _rest(self, env: Envelope, sigma: np.ndarray) -> MoveRest:
        """The `MoveRest` of this move's path at sigma."""
        quintic = quintic_rows(sigma)
        phi = self.phi
        n = len(sigma)
        if phi is None:
            turn = (_NO_Q, _NO_Q, _NO_Q, _NO_Q)
            hover, turned, torque = np.empty((1, 6)), np.empty((0, 4)), np.empty((0, 3))
        else:
            s = quintic[0]
            turn = q_exp_many(s * phi[0], s * phi[1], s * phi[2])
            hover, turned, torque = np.empty((n, 6)), np.empty((n, 4)), np.empty((n, 3))
        v = env.vehicle
        q0 = (float(self.q0[0]), float(self.q0[1]), float(self.q0[2]), float(self.q0[3]))
        phi_f = ZERO if phi is None else (float(phi[0]), float(phi[1]), float(phi[2]))
        rest_wrenches(v.mass_kg, v.gravity_m_s2, v.inertia_diag_kg_m2, q0, phi_f, quintic,
                      *turn, hover, turned, torque)
        return MoveRest(quintic, turned, torque, env.allocate(hover))

    def instants(self) -> np.ndarray:
        return move_instants(0.0 if self.phi is None else norm3(self.phi))

    @property
    def moves(self) -> bool:
        return self.travel > 0.0 and (self.phi is not None or any(self.dp))


class Figure(Segment):
    """The figure-infinity (`fcu.reference.trajectory.FigureInfinity`) from (p0, q0), t0 on."""

    def __init__(self, seq: int, t0: float, p0: Vec3, q0: Quat, amp: float, duration: float,
                 axis_enu: Vec3) -> None:
        self.seq, self.t0 = seq, t0
        self.figure = FigureInfinity(amp, duration, axis_enu, p0, q0)
        self.duration = duration
        self.t1 = t0 + duration
        self.end_ref = self.figure.end
        self.p_end, self.q_end = self.end_ref.p_enu_m, self.end_ref.q_enu_flu

    def starting(self, t0: float) -> None:
        """Start at t0 instead (`Move.starting`)."""
        self.t0 = t0
        self.t1 = t0 + self.duration

    def phase(self, tau: float) -> tuple[float, float, float]:
        return self.figure.phase(tau)

    def sample(self, tau: float) -> Reference:
        return self.figure.sample(tau)

    def path(self, sigma: np.ndarray, shape: FigureShape | None = None) -> Reference:
        return FigureInfinity(self.figure.amp, 1.0, self.figure.n, self.figure.p0,
                              self.figure.q0).path(sigma, shape)

    def unit_allocations(self, env: Envelope, sigma: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray]:
        """The allocations of `path(sigma)` and of its poses at rest, as
        `Envelope.omega_sq` makes them; what depends on the amplitude and the axis alone
        (`fcu.reference.trajectory.FigureShape`: its instants follow from the axis) is kept in the
        envelope for figures that differ in their start pose only (`Envelope.kept`)."""
        f = self.figure
        key = b"figure shape" + struct.pack("<q4d", len(sigma), f.amp, *f.n)
        shape = env.kept(key, len(sigma), lambda: figure_shape(f.amp, f.n, sigma))
        q0 = f.q0
        if q0 is not None and not _floats(*q0, *f.n_body):
            unit = self.path(sigma, shape)  # `wrenches` takes such an attitude for arrays
            return env.omega_sq(unit), env.omega_sq(at_rest(unit))
        v, n = env.vehicle, len(sigma)
        path_rows = env.scratch(5, n)
        path_rows[0], path_rows[1] = shape.dT, shape.ddT
        path_rows[2], path_rows[3], path_rows[4] = shape.acceleration
        unit_w, rest_w = env.scratch(n, 6), env.scratch(n, 6)
        figure_wrenches(v.mass_kg, v.gravity_m_s2, v.inertia_diag_kg_m2,
                        (1.0, 0.0, 0.0, 0.0) if q0 is None else q0, q0 is not None, f.n_body,
                        *shape.turn, path_rows, unit_w, rest_w)
        return env.allocate(unit_w), env.allocate(rest_w)

    def path_key(self) -> bytes:
        """What `path` and `instants` depend on (amplitude, axis, q0), as bytes."""
        f = self.figure
        q0 = f.q0 if f.q0 is not None else (math.nan,) * 4
        return struct.pack("<?8d", f.q0 is None, f.amp, *f.n, *q0) + b"figure"

    def instants(self) -> np.ndarray:
        """`fcu.envelope.feasibility.figure_instants` (read-only), kept per axis length: the
        phases' instants do not depend on the figure's other parameters."""
        axis_norm = norm3(self.figure.n)
        out = _FIGURE_INSTANTS.get(axis_norm)
        if out is None:
            out = figure_instants(axis_norm, self.figure.phase_instants)
            out.flags.writeable = False
            if len(_FIGURE_INSTANTS) >= 64:
                _FIGURE_INSTANTS.clear()
            _FIGURE_INSTANTS[axis_norm] = out
        return out


_FIGURE_INSTANTS: dict[float, np.ndarray] = {}  # `Figure.instants`
