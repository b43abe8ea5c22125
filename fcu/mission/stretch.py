"""Speed-timed moves stretched to what the vehicle can fly, many at once (`stretch_many`): what
`fcu.mission.planning.stretched` makes of each (its scaling, its search of the shortest
duration as far as `TimeScaling.stretches` and `TimeScaling.shortest` take it, the move
retimed where it stretches), from the same allocations by the same kernels
(`fcu.mission.verdicts.move_parts`, `fcu.envelope.excess.grid_kernel`,
`fcu.envelope.excess.bisect_kernel`), by a compiled call (`search_kernel_many`) per share of
the moves (`fcu.mission.batches`). The executor plans a mission with it
(`MissionExecutor.set_current`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import partial

import numpy as np

from common.jit import njit_loops, njit_released
from fcu.envelope.excess import bisect_kernel, fits_kernel, grid_kernel
from fcu.envelope.feasibility import (
    BISECT_TOL,
    DIFF_STEP,
    GRID_FITS,
    GRID_MAX,
    GRID_RATIO,
    STRETCH_GUARD,
    TILT_STEP_S,
    Envelope,
    TimeScaling,
)
from fcu.envelope.instants import time_order
from fcu.mission import batches
from fcu.mission.segments import Move
from fcu.mission.verdicts import Packed, move_parts, pack, rooms, samples


@njit_loops
def _search(parts: np.ndarray, gap: np.ndarray, ends: np.ndarray, use_floor: bool,
            limit: float, limit4: float, tau_up: float, tau_down: float, tilt_limit: float,
            step_limit: float, travel: float) -> tuple[float, float, float, float]:
    """`TimeScaling.stretches(travel)` on a path's parts, then `shortest()` where it
    stretches: the state that leaves (`TimeScaling.searched`: lo, hi, the shortest duration
    and a duration found fitting, NaN for none)."""
    lo, hi, fitted = grid_kernel(parts, gap, ends, use_floor, limit, limit4, tau_up, tau_down,
                                 tilt_limit, step_limit, STRETCH_GUARD, GRID_RATIO, GRID_FITS,
                                 GRID_MAX)
    if math.isnan(lo):
        return lo, hi, hi, hi if fitted else math.nan
    if lo <= travel < hi:
        lo, hi = bisect_kernel(parts, gap, ends, use_floor, limit, tau_up, tau_down,
                               tilt_limit, step_limit, lo, hi, BISECT_TOL, travel)
    if not hi - lo > BISECT_TOL * hi:
        return lo, hi, hi, hi
    if not travel < lo:  # it does not stretch: the search stops here
        return lo, hi, math.nan, math.nan
    lo, hi = bisect_kernel(parts, gap, ends, use_floor, limit, tau_up, tau_down, tilt_limit,
                           step_limit, lo, hi, BISECT_TOL, math.nan)
    if not hi - lo > BISECT_TOL * hi:
        return lo, hi, hi, hi
    return lo, hi, math.nan, math.nan


@njit_released
def search_kernel_many(m: float, g: float, inertia: tuple[float, float, float],
                       pinv: np.ndarray, packed: Packed, h2: float, floor: float,
                       limit: float, limit4: float, tau_up: float, tau_down: float,
                       tilt_limit: float, step_limit: float, use_floor: bool,
                       starts: np.ndarray, order: np.ndarray, parts: np.ndarray,
                       out: np.ndarray) -> None:
    """Each move j of `order` (of `packed`; its duration: the travel planned): its parts
    (`move_parts`) into parts[starts[j]:], in out[j, :4] the state its search leaves
    (`_search`) and in out[j, 4] whether it fits in its travel where it does not stretch (1
    or 0; NaN where it stretches: then flown at the duration the search found fitting)."""
    moving_room, om_room, _ = rooms(pinv, packed[2])
    poses = packed[0]
    for j in order:
        its, gap, ends = move_parts(j, m, g, inertia, pinv, packed, h2, floor, moving_room,
                                    om_room, parts[starts[j]:])
        travel = poses[j, 7]
        lo, hi, shortest, fit_at = _search(its, gap, ends, use_floor, limit, limit4, tau_up,
                                           tau_down, tilt_limit, step_limit, travel)
        out[j, 0], out[j, 1], out[j, 2], out[j, 3] = lo, hi, shortest, fit_at
        out[j, 4] = math.nan
        if not (shortest > travel and math.isfinite(shortest)) and not travel < lo:
            fits = fits_kernel(its, gap, ends, travel, limit, tau_up, tau_down, tilt_limit,
                               step_limit, use_floor, np.empty(its.shape[2]))
            out[j, 4] = 1.0 if fits else 0.0


def stretch_many(env: Envelope, moves: Sequence[Move]) -> list[Move]:
    """`fcu.mission.planning.stretched(move, env.vehicle)` of each move (each one
    `fcu.mission.verdicts.batched`): each with its scaling, retimed where it stretches."""
    if not moves:
        return []
    packed = pack(env, moves)
    orders = [time_order(seg.instants()) for seg in moves]
    rotors = env.pinv_t.shape[1] // 2
    sizes = [rotors * 10 * len(order.places) for order in orders]
    starts = np.zeros(len(moves), dtype=np.int64)
    np.cumsum(sizes[:-1], out=starts[1:])
    parts = np.empty(sum(sizes))
    out = np.empty((len(moves), 5))
    v = env.vehicle
    every = np.arange(len(moves))
    batches.run([partial(search_kernel_many, v.mass_kg, v.gravity_m_s2, v.inertia_diag_kg_m2,
                         env.pinv_t.T, packed, 2.0 * DIFF_STEP, env.floor, env.limit,
                         env.limit ** 4, env.tau_up, env.tau_down, env.tilt_limit,
                         env.tilt_rate_max * TILT_STEP_S, env.floor > 0.0, starts, share,
                         parts, out)
                 for share in batches.shares(every, samples(packed, every))])
    stretched: list[Move] = []
    for seg, order, start, size, state in zip(moves, orders, starts, sizes, out.tolist(),
                                              strict=True):
        its = parts[start:start + size].reshape(rotors, 10, len(order.places))
        scaling = TimeScaling(env, its, order)
        scaling.searched(*state[:4])
        if scaling.stretches(seg.travel):
            seg = seg.retimed(scaling.shortest())
        elif not math.isnan(state[4]):
            scaling.knows(seg.travel, state[4] == 1.0)
        seg.scaling = scaling
        stretched.append(seg)
    return stretched
