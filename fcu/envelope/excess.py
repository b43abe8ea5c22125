"""How far a path's most demanding actuator is past its limit: the kernel of the envelope
check (`fcu.envelope.feasibility`), pure and compiled. For a path flown in a given duration it takes
the allocation Omega_0 + Omega_1 / D^2 and its sigma-derivatives at the path's samples and
returns the largest need / limit over samples and rotors, with the actuator and the kind of
limit (`KINDS`): `excess_kernel` for the explanation, `excess_ratio` and `fits_kernel` (the
same values, on `scaling_parts`) for the search of the shortest duration (`grid_kernel`,
`bisect_kernel`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from common.jit import njit, njit_loops
from fcu.envelope.speed_bound import speed_bound_kernel


class Excess(NamedTuple):
    """The most demanding actuator over a segment's samples: `ratio` = need / limit (> 1: it
    does not fit), which actuator and limit (`kind`, one of KINDS; `number` 1..n), what it
    needs and its limit (rad/s), and the sample where it happens."""

    ratio: float
    kind: str
    number: int  # 1..n
    need: float
    limit: float
    sample: int


ROTOR = "rotor"
ROTOR_LAG = "rotor lag"
ROTOR_DOWN = "rotor slowing"
TILT = "tilt servo"
TILT_STEP = "tilt step"
ROTOR_FLOOR = "rotor floor"
KINDS = (ROTOR, ROTOR_LAG, ROTOR_DOWN, TILT, TILT_STEP, ROTOR_FLOOR)  # `excess_kernel`'s codes
FLOOR_HOVER_SHARE = 0.8  # `excess_kernel`: the floor at attitudes that hover below it
TINY = 1e-12  # squared allocation below which a rotor has no direction


@njit
def excess_kernel(om0: np.ndarray, om1: np.ndarray, dom0: np.ndarray, dom1: np.ndarray,
                  is_end: np.ndarray, duration: float, limit: float, tau_up: float,
                  tau_down: float, tilt_limit: float, step_limit: float,
                  after: np.ndarray | None = None, gap: np.ndarray | None = None,
                  floor: float = 0.0) -> tuple[float, int, int, int, float, float]:
    """The largest need / limit over samples and rotors of a path flown in `duration` s
    (module docstring): (ratio, kind code of KINDS, rotor 0..n-1, sample, need, limit). The
    tilt step is judged at the path's ends only (`is_end`), against its pose at rest. With
    `after` (the index of the next sample in time, -1 for none) and `gap` (the normalised
    time to it), each tilt's turn from one sample to the next counts too, at its mean rate:
    where a rotor's thrust reverses (a braking climb on planar rotors: lateral part zero,
    vertical part through zero) the tilt's derivative is zero at every sample, yet it turns
    half a revolution between two. A rotor slower than `floor` counts as floor / speed
    (the feedback's room below the feed-forward: it cannot lower a thrust that is
    already near zero without reversing it); where hovering at the sample's attitude
    already takes it below the floor, the floor is FLOOR_HOVER_SHARE of that hover speed."""
    u = 1.0 / (duration * duration)
    inv_d = 1.0 / duration
    best = (-1.0, 0, 0, 0, 0.0, 0.0)  # (ratio, kind, rotor, sample, need, limit) so far
    for k in range(om0.shape[0]):
        j = -1 if after is None else after[k]
        for i in range(om0.shape[1] // 2):
            lat = om0[k, 2 * i] + u * om1[k, 2 * i]
            ver = om0[k, 2 * i + 1] + u * om1[k, 2 * i + 1]
            if j >= 0 and gap is not None and gap[k] > 0.0:
                best = _turn_excess(best, om0, om1, u, j, k, i, lat, ver, gap[k] * duration,
                                    tilt_limit)
            dlat = dom0[k, 2 * i] + u * dom1[k, 2 * i]
            dver = dom0[k, 2 * i + 1] + u * dom1[k, 2 * i + 1]
            best = _rotor_excess(best, om0, k, i, lat, ver, dlat, dver, inv_d, limit, tau_up,
                                 tau_down, tilt_limit, floor)
            if is_end[k]:
                best = _step_excess(best, om0, k, i, lat, ver, step_limit)
    return best


Best = tuple[float, int, int, int, float, float]  # `excess_kernel`'s running maximum


@njit
def _turn_excess(best: Best, om0: np.ndarray, om1: np.ndarray, u: float, j: int, k: int,
                 i: int, lat: float, ver: float, span_s: float, tilt_limit: float) -> Best:
    """Rotor i's tilt turning from sample k to the next in time (j, `span_s` later), at its
    mean rate, where its thrust has a direction at both."""
    lat_j = om0[j, 2 * i] + u * om1[j, 2 * i]
    ver_j = om0[j, 2 * i + 1] + u * om1[j, 2 * i + 1]
    if lat * lat + ver * ver > TINY and lat_j * lat_j + ver_j * ver_j > TINY:
        turn = abs(math.atan2(lat * ver_j - ver * lat_j, lat * lat_j + ver * ver_j))
        mean_rate = turn / span_s
        if mean_rate / tilt_limit > best[0]:
            return mean_rate / tilt_limit, 3, i, k, mean_rate, tilt_limit
    return best


@njit
def _rotor_excess(best: Best, om0: np.ndarray, k: int, i: int, lat: float, ver: float,
                  dlat: float, dver: float, inv_d: float, limit: float, tau_up: float,
                  tau_down: float, tilt_limit: float, floor: float) -> Best:
    """Rotor i at sample k: its floor, its speed with the spin-up lead, its spin-down and its
    tilt rate, each against its limit, in that order."""
    sq = lat * lat + ver * ver
    w = math.sqrt(math.sqrt(sq))
    w_rate = tilt_rate = 0.0
    if sq > TINY:
        w_rate = (lat * dlat + ver * dver) / (2.0 * w * sq) * inv_d
        tilt_rate = (ver * dlat - lat * dver) / sq * inv_d
    if floor > 0.0:
        best = _floor_excess(best, om0, k, i, w, floor)
    c = w + tau_up * w_rate if w_rate > 0.0 else w
    if c / limit > best[0]:
        best = c / limit, 1 if w <= limit < c else 0, i, k, c, limit
    if w_rate < 0.0 and tau_down * -w_rate / max(w, TINY) > best[0]:
        best = tau_down * -w_rate / max(w, TINY), 2, i, k, -w_rate, w / tau_down
    if abs(tilt_rate) / tilt_limit > best[0]:
        best = abs(tilt_rate) / tilt_limit, 3, i, k, abs(tilt_rate), tilt_limit
    return best


@njit
def _floor_excess(best: Best, om0: np.ndarray, k: int, i: int, w: float,
                  floor: float) -> Best:
    """Rotor i slower than the floor at sample k; at an attitude where hovering already
    takes it below the floor, the motion may slow it to FLOOR_HOVER_SHARE of that hover
    speed."""
    w0 = math.sqrt(math.sqrt(om0[k, 2 * i] ** 2 + om0[k, 2 * i + 1] ** 2))
    low = min(floor, FLOOR_HOVER_SHARE * w0)
    if low > 0.0 and low / max(w, TINY) > best[0]:
        return low / max(w, TINY), 5, i, k, w, low
    return best


@njit
def _step_excess(best: Best, om0: np.ndarray, k: int, i: int, lat: float, ver: float,
                 step_limit: float) -> Best:
    """Rotor i's tilt step at a path's end (sample k) from its pose at rest."""
    d = math.atan2(lat, ver) - math.atan2(om0[k, 2 * i], om0[k, 2 * i + 1])
    step = abs(math.atan2(math.sin(d), math.cos(d)))
    if step / step_limit > best[0]:
        return step / step_limit, 4, i, k, step, step_limit
    return best


@njit_loops
def rest_rows_into(hover: np.ndarray, n: int, h2: float, floor: float, places: np.ndarray,
                   ends: np.ndarray, out: np.ndarray) -> None:
    """The rows of `parts_into` (its arguments) that follow from the poses at rest alone, the
    same for every path from the same rest (the mission check's moves of a group, made once
    for all of them): Omega_0, its difference, the lowest speed and the tilt at rest (rows
    0, 1, 4, 5, 8, 9)."""
    one = hover.shape[0] == 1
    for m in range(n):
        k = places[m]
        h, lo, hi = (0, 0, 0) if one else (k, n + k, 2 * n + k)
        for c in range(hover.shape[1]):
            i = c // 2
            v = c - 2 * i
            out[i, v, m] = hover[h, c]
            out[i, 4 + v, m] = (hover[hi, c] - hover[lo, c]) / h2
    for i in range(hover.shape[1] // 2):
        for m in range(n):
            w0 = math.sqrt(math.sqrt(out[i, 0, m] ** 2 + out[i, 1, m] ** 2))
            out[i, 8, m] = min(floor, FLOOR_HOVER_SHARE * w0)
            out[i, 9, m] = 0.0
        for m in ends:
            out[i, 9, m] = math.atan2(out[i, 0, m], out[i, 1, m])


@njit_loops
def moving_rows_into(om: np.ndarray, hover: np.ndarray, n: int, h2: float,
                     places: np.ndarray, out: np.ndarray) -> None:
    """The other rows of `parts_into` (2, 3, 6, 7: Omega_1 and its difference)."""
    one = hover.shape[0] == 1
    for m in range(n):
        k = places[m]
        h, lo, hi = (0, 0, 0) if one else (k, n + k, 2 * n + k)
        for c in range(om.shape[1]):
            i = c // 2
            v = c - 2 * i
            out[i, 2 + v, m] = om[k, c] - hover[h, c]
            out[i, 6 + v, m] = ((om[2 * n + k, c] - hover[hi, c]) -
                                (om[n + k, c] - hover[lo, c])) / h2


@njit_loops
def parts_into(om: np.ndarray, hover: np.ndarray, n: int, h2: float, floor: float,
               places: np.ndarray, ends: np.ndarray, out: np.ndarray) -> None:
    """`scaling_parts` (its arguments) into out (rotors x 10 x n, every value written),
    sample by sample: each row of the allocations is read once for all rotors (the upload
    check's yes/no verdict, `fcu.envelope.verdict`, makes them into an array it reuses)."""
    rest_rows_into(hover, n, h2, floor, places, ends, out)
    moving_rows_into(om, hover, n, h2, places, out)


@njit_loops
def scaling_parts(om: np.ndarray, hover: np.ndarray, n: int, h2: float, floor: float,
                  places: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """A path's parts for `excess_ratio` and `fits_kernel`, rotor by rotor, its n samples in
    time order (`places`: the sample at each place; rotors x 10 x n), from the allocation of
    the 1 s path at its instants, then at them -/+ DIFF_STEP (`om`, 3n rows) and of its
    poses at rest (`hover`: 3n rows, or 1 row for all of them): lat and ver of Omega_0,
    Omega_1 = Omega - Omega_0 and of their central differences (steps h2), the lowest speed
    `excess_kernel` lets the rotor slow to, min(floor, FLOOR_HOVER_SHARE x its hover speed),
    and at the places in `ends` (the path's ends) its tilt at rest, atan2(lat_0, ver_0);
    none of them depends on the duration (`parts_into`)."""
    out = np.empty((om.shape[1] // 2, 10, n))
    parts_into(om, hover, n, h2, floor, places, ends, out)
    return out


@njit_loops
def unpermuted(parts: np.ndarray, row: int, place_of: np.ndarray) -> np.ndarray:
    """Rows `row` and `row` + 1 of `scaling_parts` as samples x [lat_1, ver_1, ...] in the
    samples' own order (`place_of`: the place of each sample): Omega_0 for row 0, Omega_1
    for 2, their derivatives for 4 and 6."""
    n_rot, n = parts.shape[0], parts.shape[2]
    out = np.empty((n, 2 * n_rot))
    for k in range(n):
        m = place_of[k]
        for i in range(n_rot):
            out[k, 2 * i] = parts[i, row, m]
            out[k, 2 * i + 1] = parts[i, row + 1, m]
    return out


@njit_loops
def _rates(p: np.ndarray, k: int, u: float, inv_d: float) -> tuple[float, float, float]:
    """A rotor's speed, its rate and its tilt's rate at sample k (`p`: its parts) of the
    path flown in 1 / inv_d s, u = inv_d^2 (`excess_kernel`'s expressions)."""
    lat = p[0, k] + u * p[2, k]
    ver = p[1, k] + u * p[3, k]
    dlat = p[4, k] + u * p[6, k]
    dver = p[5, k] + u * p[7, k]
    sq = lat * lat + ver * ver
    w = math.sqrt(math.sqrt(sq))
    moving = sq > TINY
    w_rate = (lat * dlat + ver * dver) / (2.0 * w * sq) * inv_d if moving else 0.0
    tilt_rate = (ver * dlat - lat * dver) / sq * inv_d if moving else 0.0
    return w, w_rate, tilt_rate


@njit_loops
def _rotor_needs(p: np.ndarray, u: float, inv_d: float, limit: float, tau_up: float,
                 tau_down: float, tilt_limit: float, use_floor: bool, out: np.ndarray
                 ) -> None:
    """A rotor's largest need at each sample (`p`: its parts) from its speed, floor, lag,
    slowing and tilt rate (`excess_kernel`'s expressions, without branches: a loop the
    compiler vectorises)."""
    for k in range(p.shape[1]):
        w, w_rate, tilt_rate = _rates(p, k, u, inv_d)
        w_min = max(w, TINY)
        m = -1.0
        low = p[8, k]
        r = low / w_min
        m = r if use_floor and low > 0.0 and r > m else m
        c = w + tau_up * w_rate if w_rate > 0.0 else w
        r = c / limit
        m = r if r > m else m
        r = tau_down * -w_rate / w_min
        m = r if w_rate < 0.0 and r > m else m
        r = abs(tilt_rate) / tilt_limit
        out[k] = r if r > m else m


@njit_loops
def _rotor_beyond(p: np.ndarray, u: float, inv_d: float, limit: float, tau_up: float,
                  tau_down: float, tilt_limit: float, use_floor: bool) -> int:
    """How many of `_rotor_needs`' candidates exceed 1, each compared without its division:
    for doubles a and b > 0, the rounded a / b exceeds 1 exactly where a > b (rounding is
    monotone, and a >= the next double after b puts a / b above 1 + 2^-53)."""
    beyond = 0
    for k in range(p.shape[1]):
        w, w_rate, tilt_rate = _rates(p, k, u, inv_d)
        w_min = max(w, TINY)
        low = p[8, k]
        c = w + tau_up * w_rate if w_rate > 0.0 else w
        floor_beyond = use_floor & (low > 0.0) & (low > w_min)
        slowing_beyond = (w_rate < 0.0) & (tau_down * -w_rate > w_min)
        beyond += (floor_beyond | (c > limit) | slowing_beyond |
                   (abs(tilt_rate) > tilt_limit))
    return beyond


@njit_loops
def _largest(x: np.ndarray, best: float) -> float:
    """The largest of `best` and the values of x (NaNs passed over), four running maxima at
    once (the largest does not depend on the order the values are met in)."""
    b0 = b1 = b2 = b3 = best
    n = x.shape[0]
    for k in range(0, n - 3, 4):
        b0 = x[k] if x[k] > b0 else b0
        b1 = x[k + 1] if x[k + 1] > b1 else b1
        b2 = x[k + 2] if x[k + 2] > b2 else b2
        b3 = x[k + 3] if x[k + 3] > b3 else b3
    for k in range(n - n % 4, n):
        b0 = x[k] if x[k] > b0 else b0
    b0 = b1 if b1 > b0 else b0
    b2 = b3 if b3 > b2 else b2
    return b2 if b2 > b0 else b0


@njit
def _turn(p: np.ndarray, m: int, u: float) -> float:
    """The angle a rotor's tilt turns through from instant m to m + 1 (its lateral and
    vertical parts at u = 1 / duration^2, the angle between them)."""
    lat = p[0, m] + u * p[2, m]
    ver = p[1, m] + u * p[3, m]
    lat_j = p[0, m + 1] + u * p[2, m + 1]
    ver_j = p[1, m + 1] + u * p[3, m + 1]
    return abs(math.atan2(lat * ver_j - ver * lat_j, lat * lat_j + ver * ver_j))


@njit_loops
def _turn_flags(p: np.ndarray, gap: np.ndarray, u: float, duration: float,
                tilt_limit: float, best: float, out: np.ndarray) -> None:
    """out[m] = 1 where a rotor's tilt turns from the sample at place m to the next in time
    at a mean rate whose need could beat `best` (`excess_ratio`), else 0 (`p`: its parts,
    `gap`: the normalised time from each place to the next, 0 for none)."""
    for m in range(p.shape[1] - 1):
        lat = p[0, m] + u * p[2, m]
        ver = p[1, m] + u * p[3, m]
        lat_j = p[0, m + 1] + u * p[2, m + 1]
        ver_j = p[1, m + 1] + u * p[3, m + 1]
        g = gap[m]
        y = lat * ver_j - ver * lat_j
        x = lat * lat_j + ver * ver_j
        gd = g * duration
        room = best * x * (gd * tilt_limit)
        turns = (g > 0.0) & (lat * lat + ver * ver > TINY) & \
            (lat_j * lat_j + ver_j * ver_j > TINY)
        below = (x > 0.0) & (room > 1e-290) & (room < 1e290) & \
            (abs(y) * (1.0 + 1e-9) <= room)
        out[m] = 1.0 if turns and not below else 0.0


@njit_loops
def excess_ratio(parts: np.ndarray, gap: np.ndarray, ends: np.ndarray, duration: float,
                 limit: float, tau_up: float, tau_down: float, tilt_limit: float,
                 step_limit: float, use_floor: bool, stop: float, scratch: np.ndarray
                 ) -> float:
    """`excess_kernel`'s ratio alone, the same value to the bit (the same candidates from
    the same expressions; their largest does not depend on the order they are met in), on
    `scaling_parts` (samples in time order; `gap`: the normalised time from each place to the
    next, 0 for none; `ends`: the places of the path's ends): each rotor's needs
    (`_rotor_needs`), then the tilts' turns to the next sample, then the tilt steps at the
    ends. Returned as soon as it exceeds `stop` (the value so far then: enough to tell). A
    turn takes an atan2 only where its bound (atan t <= t, with a margin far above the
    rounding) could beat the largest need so far (`_turn_flags`), a tilt step only where
    the tilt has moved from its tilt at rest. `scratch`: room for a value per sample."""
    u = 1.0 / (duration * duration)
    inv_d = 1.0 / duration
    n_rot, n = parts.shape[0], parts.shape[2]
    best = -1.0
    for i in range(n_rot):
        _rotor_needs(parts[i], u, inv_d, limit, tau_up, tau_down, tilt_limit, use_floor,
                     scratch)
        best = _largest(scratch[:n], best)
        if best > stop:
            return best
    for i in range(n_rot):
        p = parts[i]
        _turn_flags(p, gap, u, duration, tilt_limit, best, scratch)
        for m in range(n - 1):
            if scratch[m] == 0.0:
                continue
            mean_rate = _turn(p, m, u) / (float(gap[m]) * duration)
            if mean_rate / tilt_limit > best:
                best = mean_rate / tilt_limit
                if best > stop:
                    return best
    for m in ends:
        for i in range(n_rot):
            p = parts[i]
            d = math.atan2(p[0, m] + u * p[2, m], p[1, m] + u * p[3, m]) - p[9, m]
            step = abs(math.atan2(math.sin(d), math.cos(d))) if d != 0.0 else 0.0
            if step / step_limit > best:
                best = step / step_limit
    return best


@njit_loops
def fits_kernel(parts: np.ndarray, gap: np.ndarray, ends: np.ndarray, duration: float,
                limit: float, tau_up: float, tau_down: float, tilt_limit: float,
                step_limit: float, use_floor: bool, scratch: np.ndarray) -> bool:
    """excess_ratio(...) <= 1, the same answer to the bit (its arguments; every candidate
    at most 1): the rotors' needs without their divisions (`_rotor_beyond`), an atan2
    only for a turn whose bound could exceed 1, and a tilt step only where the tilt has
    moved from its tilt at rest."""
    u = 1.0 / (duration * duration)
    inv_d = 1.0 / duration
    n_rot, n = parts.shape[0], parts.shape[2]
    for i in range(n_rot):
        if _rotor_beyond(parts[i], u, inv_d, limit, tau_up, tau_down, tilt_limit,
                         use_floor) > 0:
            return False
    for i in range(n_rot):
        p = parts[i]
        _turn_flags(p, gap, u, duration, tilt_limit, 1.0, scratch)
        for m in range(n - 1):
            if scratch[m] == 0.0:
                continue
            if _turn(p, m, u) / (gap[m] * duration) > tilt_limit:
                return False
    for m in ends:
        for i in range(n_rot):
            p = parts[i]
            d = math.atan2(p[0, m] + u * p[2, m], p[1, m] + u * p[3, m]) - p[9, m]
            if d != 0.0 and abs(math.atan2(math.sin(d), math.cos(d))) > step_limit:
                return False
    return True


@njit_loops
def grid_kernel(parts: np.ndarray, gap: np.ndarray, ends: np.ndarray, use_floor: bool,
                limit: float, limit4: float, tau_up: float, tau_down: float,
                tilt_limit: float, step_limit: float, guard: float, grid_ratio: float,
                grid_fits: int, grid_max: int) -> tuple[float, float, bool]:
    """The grid of `fcu.envelope.feasibility.TimeScaling._search` (its steps, in its order, on
    `scaling_parts`): (NaN, the shortest duration, whether the grid found it fitting) where
    the grid decides it, else (the last failing duration, the first fitting one after it,
    True) for `bisect_kernel`. Only a failing duration takes its ratio (`excess_ratio`,
    counted up to 1e6); every other is judged as fitting or not (`fits_kernel`)."""
    speed_bound = speed_bound_kernel(parts, limit4, guard)
    if not math.isfinite(speed_bound):
        return math.nan, math.inf, False
    moves = False
    for i in range(parts.shape[0]):
        for row in range(2, 6):  # Omega_1 and the derivative of Omega_0
            for k in range(parts.shape[2]):
                if parts[i, row, k] != 0.0:
                    moves = True
    if not moves:  # nothing moves: no rates
        return math.nan, speed_bound, False
    scratch = np.empty(parts.shape[2])
    d = 1e-3 if 1e-3 > speed_bound else speed_bound
    start = d
    last_fail, first_fit, run = math.nan, d, 0
    for _ in range(grid_max):
        if fits_kernel(parts, gap, ends, d, limit, tau_up, tau_down, tilt_limit, step_limit,
                       use_floor, scratch):
            if run == 0:
                first_fit = d
            run += 1
            if run >= grid_fits:
                if math.isnan(last_fail):  # the speed bound (or 1 ms) already fits
                    return math.nan, start, True
                return last_fail, first_fit, True
            d *= grid_ratio
        else:
            ratio = excess_ratio(parts, gap, ends, d, limit, tau_up, tau_down, tilt_limit,
                                 step_limit, use_floor, 1e6, scratch)
            last_fail, run = d, 0
            grow = (1e6 if 1e6 < ratio else ratio) ** (1.0 / 3.0)
            d *= grow if grow > grid_ratio else grid_ratio
    return math.nan, math.inf, False


@njit_loops
def bisect_kernel(parts: np.ndarray, gap: np.ndarray, ends: np.ndarray, use_floor: bool,
                  limit: float, tau_up: float, tau_down: float, tilt_limit: float,
                  step_limit: float, lo: float, hi: float, bisect_tol: float, until: float
                  ) -> tuple[float, float]:
    """The bisection of `fcu.envelope.feasibility.TimeScaling._search` between a failing duration lo
    and a fitting one hi (`grid_kernel`), each midpoint judged by `fits_kernel`: (lo, hi)
    once hi - lo <= bisect_tol hi, or before, once `until` lies outside [lo, hi) (NaN:
    never). Resumed from where it stopped, it takes the same steps."""
    scratch = np.empty(parts.shape[2])
    while hi - lo > bisect_tol * hi and (until != until or lo <= until < hi):
        mid = 0.5 * (lo + hi)
        if fits_kernel(parts, gap, ends, mid, limit, tau_up, tau_down, tilt_limit,
                       step_limit, use_floor, scratch):
            hi = mid
        else:
            lo = mid
    return lo, hi
