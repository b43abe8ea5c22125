"""Whether a path flown in a given duration fits the envelope, judged straight from the
allocations of its 1 s path and of its poses at rest (`fits_raw`): the answer of
`fcu.envelope.excess.fits_kernel` on `fcu.envelope.excess.scaling_parts` to the bit, with each
rotor's parts made in turn into one small array (`rotor_parts`, the same values) rather than all of
them kept. An upload check asks most paths that one question only
(`fcu.envelope.feasibility.TimeScaling` makes the parts when more is asked)."""

from __future__ import annotations

import math

import numpy as np

from common.jit import njit_loops
from fcu.envelope.excess import FLOOR_HOVER_SHARE, _rotor_beyond, _turn, _turn_flags


@njit_loops
def rotor_parts(om: np.ndarray, hover: np.ndarray, n: int, h2: float, floor: float,
                places: np.ndarray, ends: np.ndarray, i: int, p: np.ndarray) -> None:
    """Rotor i's rows of `fcu.envelope.excess.scaling_parts` (its arguments) into p (10 x n), from
    the same expressions."""
    one = hover.shape[0] == 1
    for m in range(n):
        k = places[m]
        h, lo, hi = (0, 0, 0) if one else (k, n + k, 2 * n + k)
        for v in range(2):
            c = 2 * i + v
            p[v, m] = hover[h, c]
            p[2 + v, m] = om[k, c] - hover[h, c]
            p[4 + v, m] = (hover[hi, c] - hover[lo, c]) / h2
            p[6 + v, m] = ((om[2 * n + k, c] - hover[hi, c]) -
                           (om[n + k, c] - hover[lo, c])) / h2
    for m in range(n):
        w0 = math.sqrt(math.sqrt(p[0, m] ** 2 + p[1, m] ** 2))
        p[8, m] = min(floor, FLOOR_HOVER_SHARE * w0)
        p[9, m] = 0.0
    for m in ends:
        p[9, m] = math.atan2(p[0, m], p[1, m])


@njit_loops
def fits_raw(om: np.ndarray, hover: np.ndarray, h2: float, floor: float, places: np.ndarray,
             gap: np.ndarray, ends: np.ndarray, duration: float, limit: float, tau_up: float,
             tau_down: float, tilt_limit: float, step_limit: float, use_floor: bool) -> bool:
    """`fcu.envelope.excess.fits_kernel` of the parts `fcu.envelope.excess.scaling_parts`
    makes from om, hover, h2, floor, places and ends (`gap`: the normalised time from each
    place to the next), to the bit: rotor by rotor, its needs, its tilt's turns and its tilt
    steps (a yes/no answer does not depend on the order they are met in)."""
    n = places.shape[0]
    u = 1.0 / (duration * duration)
    inv_d = 1.0 / duration
    p = np.empty((10, n))
    flags = np.empty(n)
    for i in range(om.shape[1] // 2):
        rotor_parts(om, hover, n, h2, floor, places, ends, i, p)
        if _rotor_beyond(p, u, inv_d, limit, tau_up, tau_down, tilt_limit, use_floor) > 0:
            return False
        _turn_flags(p, gap, u, duration, tilt_limit, 1.0, flags)
        for m in range(n - 1):
            if flags[m] != 0.0 and _turn(p, m, u) / (gap[m] * duration) > tilt_limit:
                return False
        for m in ends:
            d = math.atan2(p[0, m] + u * p[2, m], p[1, m] + u * p[3, m]) - p[9, m]
            if d != 0.0 and abs(math.atan2(math.sin(d), math.cos(d))) > step_limit:
                return False
    return True
