"""Whether planned moves fit the envelope in their planned durations, many at once
(`fits_many`): what `fcu.envelope.scaling.TimeScaling.fits` answers for each, from the same
allocations by the same kernels, in a compiled call (`fits_kernel_many`) per share of the
moves (`fcu.mission.batches`) instead of a scaling, three compiled calls and numpy's product
per move. The product is numpy's own BLAS call (`common.gemm.gemm_nt`), so every allocation is
the one `Envelope.allocate` makes, to the bit. The mission check and the re-check at
MISSION_START ask this of every move first, and explain only a move that does not fit
(`fcu.mission.planning.envelope_reason`).
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import partial
from typing import cast

import numpy as np

from common.gemm import AVAILABLE, gemm_nt
from common.jit import njit_loops, njit_released
from common.wire.mission_items import MissionItem
from fcu.envelope.excess import fits_kernel, moving_rows_into, parts_into, rest_rows_into
from fcu.envelope.feasibility import DIFF_STEP, TILT_STEP_S, Envelope, envelope
from fcu.envelope.instants import time_order
from fcu.mission import batches
from fcu.mission.limits import MissionLimits
from fcu.mission.planning import envelope_reason
from fcu.mission.segments import Move, MoveRest, Segment, _floats, move_wrenches

_I = np.int64


Packed = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
               np.ndarray, np.ndarray, np.ndarray, np.ndarray]  # `pack`


@njit_loops
def allocated(j: int, m: float, g: float, inertia: tuple[float, float, float],
              pinv: np.ndarray, packed: Packed, moving_room: np.ndarray,
              om_room: np.ndarray) -> np.ndarray:
    """Move j of `packed`: its wrenches (`move_wrenches` from its q0, dp and its group's
    `MoveRest`) into the start of `moving_room`, and their allocation (A^+ = pinv, rotors'
    rows x 6, as numpy's product) into the start of `om_room`, which is returned."""
    poses, groups, index, quintic, turned, torque = packed[:6]
    row = index[groups[j]]
    rows = 3 * row[0]
    moving = moving_room[:rows]
    pose = poses[j]
    move_wrenches(m, g, inertia, (pose[0], pose[1], pose[2], pose[3]),
                  (pose[4], pose[5], pose[6]), quintic[:, row[1]:row[1] + rows],
                  turned[row[2]:row[2] + row[3]], torque[row[2]:row[2] + row[3]], moving)
    om = om_room[:rows]
    gemm_nt(moving, pinv, om)
    return om


@njit_loops
def move_parts(j: int, m: float, g: float, inertia: tuple[float, float, float],
               pinv: np.ndarray, packed: Packed, h2: float, floor: float,
               moving_room: np.ndarray, om_room: np.ndarray, room: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(the parts, gaps and ends of move j of `packed`), the parts (`parts_into`, rotors x 10
    x n) into the start of `room`, from its allocation (`allocated`)."""
    hover, places, gap, ends = packed[6:]
    row = packed[2][packed[1][j]]
    n = row[0]
    om = allocated(j, m, g, inertia, pinv, packed, moving_room, om_room)
    cols = pinv.shape[0]
    parts = room[:(cols // 2) * 10 * n].reshape((cols // 2, 10, n))
    its_ends = ends[row[7]:row[7] + row[8]]
    parts_into(om, hover[row[4]:row[4] + row[5]], n, h2, floor, places[row[6]:row[6] + n],
               its_ends, parts)
    return parts, gap[row[6]:row[6] + n], its_ends


@njit_loops
def rooms(pinv: np.ndarray, index: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Room for `move_parts`' wrenches, allocations and parts of the largest group."""
    most = 1
    for k in range(index.shape[0]):
        most = max(most, index[k, 0])
    cols = pinv.shape[0]
    return (np.empty((3 * most, 6)), np.empty((3 * most, cols)),
            np.empty((cols // 2) * 10 * most))


@njit_released
def fits_kernel_many(m: float, g: float, inertia: tuple[float, float, float],
                     pinv: np.ndarray, packed: Packed, h2: float, floor: float,
                     limit: float, tau_up: float, tau_down: float, tilt_limit: float,
                     step_limit: float, use_floor: bool, order: np.ndarray,
                     out: np.ndarray) -> None:
    """out[j] = whether move j of `packed` fits in its duration, for each j of `order`: its
    parts (`move_parts`' values) judged by `fits_kernel`. With the moves in `group_order`,
    the rows of the parts that a group shares (`rest_rows_into`) are made once per group."""
    moving_room, om_room, room = rooms(pinv, packed[2])
    poses, groups, index = packed[:3]
    hover, places, gap, ends = packed[6:]
    cols = pinv.shape[0]
    last = -1
    for j in order:
        gi = groups[j]
        row = index[gi]
        n = row[0]
        parts = room[:(cols // 2) * 10 * n].reshape((cols // 2, 10, n))
        its_hover = hover[row[4]:row[4] + row[5]]
        its_places = places[row[6]:row[6] + n]
        its_ends = ends[row[7]:row[7] + row[8]]
        if gi != last:
            rest_rows_into(its_hover, n, h2, floor, its_places, its_ends, parts)
            last = gi
        om = allocated(j, m, g, inertia, pinv, packed, moving_room, om_room)
        moving_rows_into(om, its_hover, n, h2, its_places, parts)
        out[j] = fits_kernel(parts, gap[row[6]:row[6] + n], its_ends, poses[j, 7], limit,
                             tau_up, tau_down, tilt_limit, step_limit, use_floor, np.empty(n))


def group_order(packed: Packed) -> np.ndarray:
    """The moves of `packed` group by group, each group's in their own order."""
    return np.argsort(packed[1], kind="mergesort")


def samples(packed: Packed, order: np.ndarray) -> np.ndarray:
    """The samples of each move of `order` (the work a kernel does on it)."""
    index, groups = packed[2], packed[1]
    return np.asarray(index[groups[order], 0])


def compiled_product(env: Envelope) -> bool:
    """Whether numpy's product can be called from compiled code with A^+ laid out as
    `Envelope` makes it."""
    return AVAILABLE and env.pinv_t.T.flags.c_contiguous and env.pinv_t.shape[1] > 1


def batched(env: Envelope, seg: Move) -> bool:
    """Whether `fits_many` judges this move itself (else the caller asks its scaling): a
    move whose allocations `Move.unit_allocations` makes (a float q0 and dp), where
    `compiled_product`."""
    return compiled_product(env) and _floats(*seg.q0) and _floats(*seg.dp)


def pack(env: Envelope, moves: Sequence[Move]) -> Packed:
    """The moves (each one `batched`) for `move_parts`: a row per move of q0, dp and its
    duration; its group (the same instants and `MoveRest`); a row per group of `index`
    (samples n, then the offsets of its quintic's columns, of its rows of turned and torque
    and how many: 0 where it keeps its attitude, of its rows of hover and how many: 1 or 3n,
    of its places and gaps, of its ends and how many); the groups' arrays one after
    another."""
    groups: dict[int, int] = {}  # by the `MoveRest` (kept in members): its q0, phi, instants
    same: dict[tuple[float, ...], int] = {}  # the group of each q0 and phi met (no zero:
    # 0.0 and -0.0 are equal keys, different rests)
    members: list[tuple[MoveRest, np.ndarray, np.ndarray, np.ndarray, int]] = []
    group_of: list[int] = []
    poses: list[tuple[float, ...]] = []
    for seg in moves:
        turn = (*seg.q0, *(seg.phi if seg.phi is not None else ()))
        gi = same.get(turn)
        if gi is None:  # the instants follow from phi, the rest from q0 and phi
            order = time_order(seg.instants())
            rest = seg.rest(env, order.stepped)
            gi = groups.get(id(rest))
            if gi is None:
                gi = groups[id(rest)] = len(members)
                members.append((rest, order.places, order.place_gap, order.place_ends,
                                len(order.places)))
            if 0.0 not in turn:
                same[turn] = gi
        group_of.append(gi)
        poses.append((*seg.q0, *seg.dp, seg.duration))
    index = np.empty((len(members), 9), dtype=_I)
    offsets = [0, 0, 0, 0, 0]  # quintic columns, turned rows, hover rows, samples, ends
    for gi, (rest, _, _, ends, n) in enumerate(members):
        turns, held = rest.turned.shape[0], rest.hover.shape[0]
        index[gi] = (n, offsets[0], offsets[1], turns, offsets[2], held, offsets[3],
                     offsets[4], len(ends))
        offsets[0] += 3 * n
        offsets[1] += turns
        offsets[2] += held
        offsets[3] += n
        offsets[4] += len(ends)
    return (np.array(poses, dtype=np.float64), np.array(group_of, dtype=_I), index,
            np.concatenate([r.quintic for r, *_ in members], axis=1),
            np.concatenate([r.turned for r, *_ in members]),
            np.concatenate([r.torque for r, *_ in members]),
            np.concatenate([r.hover for r, *_ in members]),
            np.concatenate([p for _, p, *_ in members]),
            np.concatenate([g for _, _, g, *_ in members]),
            np.concatenate([e for *_, e, _ in members]))


def fits_many(env: Envelope, moves: Sequence[Move]) -> list[bool]:
    """`env.scaling(move).fits(move.duration)` of each move (each one `batched`), the same
    answers, by a compiled call per share of the moves (`fcu.mission.batches`)."""
    if not moves:
        return []
    out = np.empty(len(moves), dtype=np.bool_)
    v = env.vehicle
    packed = pack(env, moves)
    order = group_order(packed)
    batches.run([partial(fits_kernel_many, v.mass_kg, v.gravity_m_s2, v.inertia_diag_kg_m2,
                         env.pinv_t.T, packed, 2.0 * DIFF_STEP, env.floor, env.limit,
                         env.tau_up, env.tau_down, env.tilt_limit,
                         env.tilt_rate_max * TILT_STEP_S, env.floor > 0.0, share, out)
                 for share in batches.shares(order, samples(packed, order))])
    return [bool(x) for x in out]


Planned = tuple[MissionItem, Segment, MissionLimits]  # an item, its segment, its limits


def _judging(limits: MissionLimits) -> Envelope | None:
    """The envelope `fits_many` judges the moves planned with `limits` in (None: none)."""
    if limits.vehicle is None:
        return None
    env = envelope(limits.vehicle)
    return env if compiled_product(env) else None


def _judged_here(seg: Segment) -> bool:
    """Whether `envelope_reason` of this segment, planned with limits that `_judging` gives
    an envelope for, is "" exactly when its scaling fits its duration and `fits_many` can
    tell that (an unscaled move)."""
    return isinstance(seg, Move) and seg.scaling is None and seg.duration > 0.0 and \
        seg.moves and _floats(*seg.q0, *seg.dp)


def first_refusal(planned: Sequence[Planned]) -> tuple[int, str]:
    """(the index, the reason) of the first planned segment the vehicle cannot fly
    (`fcu.mission.planning.envelope_reason`), or (-1, ""): the moves `fits_many` can judge
    judged at once, then, in order, each of the others and each move that does not fit
    explained as before (the same reasons)."""
    by_env: dict[int, tuple[Envelope, list[int]]] = {}
    envs: dict[int, Envelope | None] = {}  # `_judging` by the limits (the same few)
    for k, (_, seg, limits) in enumerate(planned):
        key = id(limits)
        if key in envs:
            env = envs[key]
        else:
            env = envs[key] = _judging(limits)
        if env is not None and _judged_here(seg):
            by_env.setdefault(id(env), (env, []))[1].append(k)
    fits: dict[int, bool] = {}
    for env, ks in by_env.values():
        moves = [planned[k][1] for k in ks]
        fits.update(zip(ks, fits_many(env, cast(list[Move], moves)), strict=True))
    for k, (item, seg, limits) in enumerate(planned):
        if fits.get(k, False):
            continue
        reason = envelope_reason(item, seg, limits)
        if reason:
            return k, reason
    return -1, ""
