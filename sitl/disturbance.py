"""Body-frame (FLU) force and torque disturbances of the Case II profiles (docs/model.md#scenarios).

The terms are a flat table (`terms_table`, one row per term) that a compiled kernel
(`disturbance_kernel`, numba) sums; the plant's step kernel calls it at its RK4 stage times.
"""

from __future__ import annotations

import math

import numpy as np

from common.config.scenario_terms import DisturbanceTerm
from common.jit import njit
from sitl.layouts import (
    D_AMPLITUDE,
    D_END,
    D_OMEGA,
    D_PART,
    D_PHASE,
    D_PULSE,
    D_SIZE,
    D_START,
    DISTURBANCE_TERM,
)

Vec3 = tuple[float, float, float]
_ZERO: Vec3 = (0.0, 0.0, 0.0)


def terms_table(force_terms: tuple[DisturbanceTerm, ...],
                torque_terms: tuple[DisturbanceTerm, ...]) -> np.ndarray:
    """The kernel's table of the terms (one DISTURBANCE_TERM row each, its fields in order),
    force terms first, each part in its order."""
    assert DISTURBANCE_TERM.names() == ("part", "pulse", "start_s", "end_s", "omega_rad_s",
                                        "phase_rad", "amplitude")
    rows = [(float(part), 1.0 if term.kind == "pulse" else 0.0, term.start_s, term.end_s,
             term.omega_rad_s, term.phase_rad, *term.amplitude)
            for part, terms in ((0, force_terms), (1, torque_terms)) for term in terms]
    return np.array(rows, dtype=np.float64).reshape(-1, D_SIZE)


@njit
def disturbance_kernel(terms: np.ndarray, t_s: float) -> tuple[Vec3, Vec3]:
    """(force_flu_n, torque_flu_nm) at time t_s (the scenario's clock): the sum of the pulse
    terms active at t_s and of the sine terms amplitude sin(omega t + phase)."""
    fx = fy = fz = tx = ty = tz = 0.0
    for j in range(terms.shape[0]):
        row = terms[j]
        if t_s < row[D_START] or t_s >= row[D_END]:
            continue
        k = 1.0 if row[D_PULSE] != 0.0 else math.sin(row[D_OMEGA] * t_s + row[D_PHASE])
        a = D_AMPLITUDE
        if row[D_PART] == 0.0:
            fx += k * row[a]
            fy += k * row[a + 1]
            fz += k * row[a + 2]
        else:
            tx += k * row[a]
            ty += k * row[a + 1]
            tz += k * row[a + 2]
    return (fx, fy, fz), (tx, ty, tz)


class Disturbance:
    """Sum of pulse and sine terms; `wrench(t)` is a pure function of time, the scenario's
    times counted from `t0_s` (the flight's start: after the estimator's alignment)."""

    def __init__(self, force_terms: tuple[DisturbanceTerm, ...] = (),
                 torque_terms: tuple[DisturbanceTerm, ...] = (), t0_s: float = 0.0) -> None:
        self.force_terms = force_terms
        self.torque_terms = torque_terms
        self.t0_s = t0_s
        self.table = terms_table(force_terms, torque_terms)

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
        return disturbance_kernel(self.table, float(t_s) - self.t0_s)
