"""Planned segments: one mission item each, sampled at tau = t - t0.

A move is the minimum-jerk quintic of `fcu.trajectory` in position and along the shortest
rotation in attitude, then a hold; a figure is `fcu.trajectory.FigureInfinity`. Both sample
one instant (`sample`) or, for the envelope check, a whole normalised path at once (`path`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from common.frames import q_ned_frd_to_enu_flu
from common.quaternion import q_exp_many
from fcu.dualquat import Quat, Vec3, norm3, q_exp, q_mul
from fcu.feasibility import TimeScaling, figure_instants, move_instants
from fcu.tracker import Reference, pose_ref
from fcu.trajectory import FigureInfinity, quintic, quintic_poly

ZERO: Vec3 = (0.0, 0.0, 0.0)


def level_attitude(yaw_ned_deg: float) -> Quat:
    """Level attitude (ENU/FLU) heading at a NED yaw in degrees."""
    return q_ned_frd_to_enu_flu(q_exp((0.0, 0.0, math.radians(yaw_ned_deg))))


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

    def path(self, sigma: np.ndarray) -> Reference:  # pragma: no cover - overridden
        """The moving part flown in 1 s, at normalised times sigma (arrays)."""
        raise NotImplementedError

    def instants(self) -> np.ndarray:  # pragma: no cover - overridden
        """Normalised times at which the envelope is checked."""
        raise NotImplementedError


class Move(Segment):
    """Quintic move p0 -> p0 + dp, q0 -> q0 exp(phi) in `travel` s, then hold `hold` s."""

    def __init__(self, seq: int, t0: float, p0: Vec3, dp: Vec3, q0: Quat, phi: Vec3 | None,
                 travel: float, hold: float) -> None:
        self.seq, self.t0 = seq, t0
        self.p0, self.dp, self.q0, self.phi = p0, dp, q0, phi
        self.travel = self.duration = travel
        self.hold = hold
        self.t1 = t0 + travel + hold
        self.p_end = (p0[0] + dp[0], p0[1] + dp[1], p0[2] + dp[2])
        self.q_end = q0 if phi is None else q_mul(q0, q_exp(phi))
        self.end_ref = pose_ref(self.p_end, self.q_end)

    def retimed(self, travel: float) -> Move:
        return Move(self.seq, self.t0, self.p0, self.dp, self.q0, self.phi, travel, self.hold)

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

    def instants(self) -> np.ndarray:
        return move_instants(0.0 if self.phi is None else norm3(self.phi))

    @property
    def moves(self) -> bool:
        return self.travel > 0.0 and (self.phi is not None or any(self.dp))


class Figure(Segment):
    """The figure-infinity (`fcu.trajectory.FigureInfinity`) from (p0, q0), t0 on."""

    def __init__(self, seq: int, t0: float, p0: Vec3, q0: Quat, amp: float, duration: float,
                 axis_enu: Vec3) -> None:
        self.seq, self.t0 = seq, t0
        self.figure = FigureInfinity(amp, duration, axis_enu, p0, q0)
        self.duration = duration
        self.t1 = t0 + duration
        self.end_ref = self.figure.end
        self.p_end, self.q_end = self.end_ref.p_enu_m, self.end_ref.q_enu_flu

    def phase(self, tau: float) -> tuple[float, float, float]:
        return self.figure.phase(tau)

    def sample(self, tau: float) -> Reference:
        return self.figure.sample(tau)

    def path(self, sigma: np.ndarray) -> Reference:
        return FigureInfinity(self.figure.amp, 1.0, self.figure.n, self.figure.p0,
                              self.figure.q0).path(sigma)

    def instants(self) -> np.ndarray:
        return figure_instants(norm3(self.figure.n), self.figure.phase_instants)
