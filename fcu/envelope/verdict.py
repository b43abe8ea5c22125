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
from fcu.envelope.excess import _rotor_beyond, _turn, _turn_flags, rotor_parts


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
