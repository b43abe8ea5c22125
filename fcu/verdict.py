"""Whether a path flown in a given duration fits the envelope, judged straight from the
allocations of its 1 s path and of its poses at rest (`fits_raw`): `fcu.excess.fits_kernel`
on the parts `fcu.excess.scaling_parts` makes, made into room the caller keeps for the next
path rather than into a new array. An upload check asks most paths that one question only
(`fcu.scaling.TimeScaling` makes and keeps the parts when more is asked)."""

from __future__ import annotations

import numpy as np

from common.jit import njit_loops
from fcu.excess import fits_kernel, parts_into


@njit_loops
def fits_raw(om: np.ndarray, hover: np.ndarray, h2: float, floor: float, places: np.ndarray,
             gap: np.ndarray, ends: np.ndarray, duration: float, limit: float, tau_up: float,
             tau_down: float, tilt_limit: float, step_limit: float, use_floor: bool,
             room: np.ndarray, scratch: np.ndarray) -> bool:
    """`fcu.excess.fits_kernel` of the parts `fcu.excess.scaling_parts` makes from om,
    hover, h2, floor, places and ends (`gap`: the normalised time from each place to the
    next), made into `room` (rotors x 10 x samples; what it held is overwritten);
    `scratch`: room for a value per sample."""
    parts_into(om, hover, places.shape[0], h2, floor, places, ends, room)
    return fits_kernel(room, gap, ends, duration, limit, tau_up, tau_down, tilt_limit,
                       step_limit, use_floor, scratch)
