"""Whether a path flown in a given duration fits the envelope, judged straight from the
allocations of its 1 s path and of its poses at rest (`fits_raw`): the answer of
`fcu.envelope.excess.fits_kernel` on `fcu.envelope.excess.scaling_parts`, made into an array
the caller reuses rather than kept. An upload check asks most paths that one question only
(`fcu.envelope.feasibility.TimeScaling` makes the parts to keep when more is asked)."""

from __future__ import annotations

import numpy as np

from common.jit import njit_loops
from fcu.envelope.excess import fits_kernel, parts_into


@njit_loops
def fits_raw(om: np.ndarray, hover: np.ndarray, h2: float, floor: float, places: np.ndarray,
             gap: np.ndarray, ends: np.ndarray, duration: float, limit: float, tau_up: float,
             tau_down: float, tilt_limit: float, step_limit: float, use_floor: bool,
             room: np.ndarray) -> bool:
    """`fcu.envelope.excess.fits_kernel` of the parts `fcu.envelope.excess.scaling_parts`
    makes from om, hover, h2, floor, places and ends (`gap`: the normalised time from each
    place to the next), to the bit, the parts made into `room` (C-contiguous, (rotors x 10)
    x samples; its values before do not matter)."""
    n = places.shape[0]
    parts = room.reshape((om.shape[1] // 2, 10, n))
    parts_into(om, hover, n, h2, floor, places, ends, parts)
    return fits_kernel(parts, gap, ends, duration, limit, tau_up, tau_down, tilt_limit,
                       step_limit, use_floor, np.empty(n))
