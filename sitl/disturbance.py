"""Body-frame (FLU) force and torque disturbances of the Case II profiles (MODEL.md 5)."""

from __future__ import annotations

import math

from common.config import DisturbanceTerm

Vec3 = tuple[float, float, float]
_ZERO: Vec3 = (0.0, 0.0, 0.0)


def _evaluate(terms: tuple[DisturbanceTerm, ...], t_s: float) -> Vec3:
    x = y = z = 0.0
    for term in terms:
        if t_s < term.start_s or t_s >= term.end_s:
            continue
        k = 1.0 if term.kind == "pulse" else math.sin(term.omega_rad_s * t_s + term.phase_rad)
        ax, ay, az = term.amplitude
        x += k * ax
        y += k * ay
        z += k * az
    return (x, y, z)


class Disturbance:
    """Sum of pulse and sine terms; `wrench(t)` is a pure function of time, the scenario's
    times counted from `t0_s` (the flight's start: after the estimator's alignment)."""

    def __init__(self, force_terms: tuple[DisturbanceTerm, ...] = (),
                 torque_terms: tuple[DisturbanceTerm, ...] = (), t0_s: float = 0.0) -> None:
        self.force_terms = force_terms
        self.torque_terms = torque_terms
        self.t0_s = t0_s

    def from_time(self, t0_s: float) -> Disturbance:
        """The same terms with the scenario's clock starting at t0_s."""
        return Disturbance(self.force_terms, self.torque_terms, t0_s)

    @property
    def active(self) -> bool:
        return bool(self.force_terms or self.torque_terms)

    def wrench(self, t_s: float) -> tuple[Vec3, Vec3]:
        """(force_flu_n, torque_flu_nm) at time t."""
        if not self.active:
            return _ZERO, _ZERO
        t_s -= self.t0_s
        return _evaluate(self.force_terms, t_s), _evaluate(self.torque_terms, t_s)
