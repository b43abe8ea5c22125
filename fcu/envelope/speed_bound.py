"""The stretch a path needs for its rotors' speed alone, in closed form (the search's
starting point, `fcu.envelope.scaling.TimeScaling._speed_bound`): with u = 1 / D^2 each
rotor's w^4 = a u^2 + b u + (c + L^4) on `fcu.envelope.excess.scaling_parts`, the largest u
at which no rotor passes the limit L.
"""

from __future__ import annotations

import math

import numpy as np

from common.jit import njit


@njit
def speed_bound_kernel(parts: np.ndarray, limit4: float, guard: float) -> float:
    """`fcu.envelope.feasibility.TimeScaling._speed_bound` (rotor speed alone, closed form, on
    `scaling_parts`; the value does not depend on the order of the samples): w^4 = a u^2 +
    b u + (c + L^4) with u = 1 / D^2, `limit4` = L^4, `guard` its STRETCH_GUARD."""
    if _hover_beyond(parts, limit4):
        return math.inf
    bound, u_max = _largest_u(parts, limit4)
    if bound == _NO_BOUND:
        return 0.0
    if bound == _NONE_FITS or u_max <= 0.0:
        return math.inf
    return (1.0 + guard) / math.sqrt(u_max)


_NO_BOUND, _NONE_FITS, _BOUND = 0, 1, 2  # `_largest_u`'s verdicts


@njit
def _hover_beyond(parts: np.ndarray, limit4: float) -> bool:
    """Some rotor above the limit at some sample however long the path takes (u = 0)."""
    for i in range(parts.shape[0]):
        for k in range(parts.shape[2]):
            lat0, ver0 = parts[i, 0, k], parts[i, 1, k]
            if lat0 * lat0 + ver0 * ver0 - limit4 > 0.0:
                return True
    return False


@njit
def _largest_u(parts: np.ndarray, limit4: float) -> tuple[int, float]:
    """The largest u = 1 / D^2 at which every rotor keeps w^4 <= L^4 (the smallest root over
    rotors and samples; NaN if any root is NaN, as np.min): _NO_BOUND when no sample depends
    on u, _NONE_FITS when a root has no positive denominator."""
    any_bound = False
    any_nan = False
    u_max = math.inf
    for i in range(parts.shape[0]):
        for k in range(parts.shape[2]):
            lat0, ver0 = parts[i, 0, k], parts[i, 1, k]
            lat1, ver1 = parts[i, 2, k], parts[i, 3, k]
            a = lat1 * lat1 + ver1 * ver1
            if not a > 0.0:
                continue
            any_bound = True
            b = 2.0 * (lat0 * lat1 + ver0 * ver1)
            c = lat0 * lat0 + ver0 * ver0 - limit4
            disc = b * b - 4.0 * a * c
            if disc < 0.0:  # np.maximum(disc, 0.0): NaN and -0.0 kept
                disc = 0.0
            sq = math.sqrt(disc)
            num = sq - b if b < 0.0 else -2.0 * c
            den = 2.0 * a if b < 0.0 else b + sq
            if den <= 0.0:
                return _NONE_FITS, math.inf
            r = num / den
            if r != r:
                any_nan = True
            elif r < u_max:
                u_max = r
    if not any_bound:
        return _NO_BOUND, 0.0
    return _BOUND, math.nan if any_nan else u_max
