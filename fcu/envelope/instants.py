"""A path's check instants (normalised times sigma in [0, 1] at which `fcu.envelope.feasibility`
judges its envelope; its module docstring says how they are spread) and their order in
time (`SampleOrder`), kept per set of instants."""

from __future__ import annotations

import math
from functools import lru_cache
from typing import Any, NamedTuple

import numpy as np

DIFF_STEP = 1e-6  # sigma step of the central differences of a 1 s path
MOVE_SAMPLES = 64
FIGURE_STEP_RAD = 0.02  # rad of attitude and phase between a figure's samples
MOVE_STEP_RAD = 0.01  # rad of attitude between a turning move's samples
FIGURE_SAMPLES_MAX = 4096

_QUINTIC_PEAKS = (0.5 - math.sqrt(3.0) / 6.0, 0.5, 0.5 + math.sqrt(3.0) / 6.0)


_MOVE_INSTANTS = np.concatenate([np.linspace(0.0, 1.0, MOVE_SAMPLES), _QUINTIC_PEAKS])
_MOVE_INSTANTS.flags.writeable = False


@lru_cache(maxsize=64)
def _turning_instants(n: int) -> np.ndarray:
    out = np.concatenate([np.linspace(0.0, 1.0, n), _QUINTIC_PEAKS])
    out.flags.writeable = False
    return out


def move_instants(turn_rad: float = 0.0) -> np.ndarray:
    """Normalised check instants of a quintic move that turns `turn_rad`
    (`fcu.envelope.feasibility`; read-only): a tilt can swing fast where a rotor's thrust passes
    near zero as the body turns, so a turning move is sampled at most MOVE_STEP_RAD of attitude
    apart."""
    if turn_rad <= 0.0:
        return _MOVE_INSTANTS
    # the quintic's top rate is 1.875 x its mean: steps of turn / (n - 1) * 1.875 at most
    n = math.ceil(1.875 * turn_rad / MOVE_STEP_RAD) + 1
    if n <= MOVE_SAMPLES:
        return _MOVE_INSTANTS
    return _turning_instants(int(min(FIGURE_SAMPLES_MAX, 16 * math.ceil(n / 16))))


def figure_instants(axis_norm: float, phase_instants: Any) -> np.ndarray:
    """Normalised check instants of a figure whose attitude turns T |n| (T: 0 .. 2 pi);
    `phase_instants(T)` maps phases to normalised times."""
    turns = 2.0 * math.pi * max(2.0, axis_norm)
    # T' peaks at pi^2 (in 1 s), so evenly spaced instants step T by at most pi^2 / (n - 1).
    n = int(min(FIGURE_SAMPLES_MAX, max(MOVE_SAMPLES, math.ceil(
        turns * math.pi / 2.0 / FIGURE_STEP_RAD) + 1)))
    peaks = phase_instants(np.arange(1, 8) * (math.pi / 4.0))
    return np.concatenate([np.linspace(0.0, 1.0, n), peaks, [0.5]])


class SampleOrder(NamedTuple):
    """A path's check instants in time (`TimeScaling`; read-only arrays)."""

    stepped: np.ndarray  # the instants, then each - DIFF_STEP, then each + DIFF_STEP
    ends: np.ndarray  # the indices of the path's ends (sigma 0 or 1)
    after: np.ndarray  # the index of the next instant in time, -1 for none
    gap: np.ndarray  # the normalised time to it (0 for none)
    places: np.ndarray  # the index of the instant at each place in time order
    place_of: np.ndarray  # the place of each instant
    place_gap: np.ndarray  # the normalised time from each place to the next (0 for none)
    place_ends: np.ndarray  # the places of the path's ends


_ORDERS: dict[bytes, SampleOrder] = {}


_BY_ARRAY: dict[int, tuple[np.ndarray, SampleOrder]] = {}  # read-only instants, by identity


def time_order(sigma: np.ndarray) -> SampleOrder:
    """The time order of a path's check instants (`SampleOrder`), kept per set of instants
    (a read-only array, as `move_instants` gives, found by identity first)."""
    same = _BY_ARRAY.get(id(sigma))
    if same is not None and same[0] is sigma:
        return same[1]
    key = sigma.tobytes()
    hit = _ORDERS.get(key)
    if hit is None:
        hit = _time_order(sigma, key)
    if not sigma.flags.writeable:
        if len(_BY_ARRAY) >= 256:
            _BY_ARRAY.clear()
        _BY_ARRAY[id(sigma)] = sigma, hit  # kept alive with it: its id is not reused
    return hit


def _time_order(sigma: np.ndarray, key: bytes) -> SampleOrder:
    """`time_order` made (and kept by `key`, the bytes of sigma)."""
    n = len(sigma)
    ends = np.flatnonzero((sigma == 0.0) | (sigma == 1.0))
    order = np.argsort(sigma, kind="stable")
    after = np.full(n, -1, dtype=np.int64)
    after[order[:-1]] = order[1:]
    gap = np.where(after >= 0, sigma[after] - sigma, 0.0)
    places = order.astype(np.int64)
    place_of = np.empty(n, dtype=np.int64)
    place_of[places] = np.arange(n)
    stepped = np.concatenate([sigma, sigma - DIFF_STEP, sigma + DIFF_STEP])
    out = SampleOrder(stepped, ends, after, gap, places, place_of,
                      np.ascontiguousarray(gap[places]),
                      np.flatnonzero((sigma[places] == 0.0) | (sigma[places] == 1.0)))
    for x in out:
        x.flags.writeable = False
    if len(_ORDERS) >= 256:
        _ORDERS.clear()
    _ORDERS[key] = out
    return out


def clear_orders() -> None:
    """Forget the orders kept (`time_order`)."""
    _ORDERS.clear()
    _BY_ARRAY.clear()
