"""How far a path's most demanding actuator is past its limit: the kernel of the envelope
check (`fcu.feasibility`), pure and compiled. For a path flown in a given duration it takes
the allocation Omega_0 + Omega_1 / D^2 and its sigma-derivatives at the path's samples and
returns the largest need / limit over samples and rotors, with the actuator and the kind of
limit (`KINDS`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from common.jit import njit


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
    best, kind, rotor, sample, need, lim = -1.0, 0, 0, 0, 0.0, 0.0
    for k in range(om0.shape[0]):
        j = -1 if after is None else after[k]
        for i in range(om0.shape[1] // 2):
            lat = om0[k, 2 * i] + u * om1[k, 2 * i]
            ver = om0[k, 2 * i + 1] + u * om1[k, 2 * i + 1]
            if j >= 0 and gap is not None and gap[k] > 0.0:
                lat_j = om0[j, 2 * i] + u * om1[j, 2 * i]
                ver_j = om0[j, 2 * i + 1] + u * om1[j, 2 * i + 1]
                if lat * lat + ver * ver > TINY and lat_j * lat_j + ver_j * ver_j > TINY:
                    turn = abs(math.atan2(lat * ver_j - ver * lat_j, lat * lat_j + ver * ver_j))
                    mean_rate = turn / (gap[k] * duration)
                    if mean_rate / tilt_limit > best:
                        best, kind, need, lim = mean_rate / tilt_limit, 3, mean_rate, \
                            tilt_limit
                        rotor, sample = i, k
            dlat = dom0[k, 2 * i] + u * dom1[k, 2 * i]
            dver = dom0[k, 2 * i + 1] + u * dom1[k, 2 * i + 1]
            sq = lat * lat + ver * ver
            w = math.sqrt(math.sqrt(sq))
            w_rate = tilt_rate = 0.0
            if sq > TINY:
                w_rate = (lat * dlat + ver * dver) / (2.0 * w * sq) * inv_d
                tilt_rate = (ver * dlat - lat * dver) / sq * inv_d
            if floor > 0.0:
                # at an attitude where hovering already takes a rotor below the floor, the
                # motion may slow it to FLOOR_HOVER_SHARE of that hover speed
                w0 = math.sqrt(math.sqrt(om0[k, 2 * i] ** 2 + om0[k, 2 * i + 1] ** 2))
                low = min(floor, FLOOR_HOVER_SHARE * w0)
                if low > 0.0 and low / max(w, TINY) > best:
                    best, kind, need, lim = low / max(w, TINY), 5, w, low
                    rotor, sample = i, k
            c = w + tau_up * w_rate if w_rate > 0.0 else w
            if c / limit > best:
                best, kind, need, lim = c / limit, 1 if w <= limit < c else 0, c, limit
                rotor, sample = i, k
            if w_rate < 0.0 and tau_down * -w_rate / max(w, TINY) > best:
                best, kind, need, lim = tau_down * -w_rate / max(w, TINY), 2, -w_rate, \
                    w / tau_down
                rotor, sample = i, k
            if abs(tilt_rate) / tilt_limit > best:
                best, kind, need, lim = abs(tilt_rate) / tilt_limit, 3, abs(tilt_rate), \
                    tilt_limit
                rotor, sample = i, k
            if is_end[k]:
                d = math.atan2(lat, ver) - math.atan2(om0[k, 2 * i], om0[k, 2 * i + 1])
                step = abs(math.atan2(math.sin(d), math.cos(d)))
                if step / step_limit > best:
                    best, kind, need, lim = step / step_limit, 4, step, step_limit
                    rotor, sample = i, k
    return best, kind, rotor, sample, need, lim


@njit
def pair_parts(om0: np.ndarray, om1: np.ndarray, dom0: np.ndarray, dom1: np.ndarray,
               floor: float) -> np.ndarray:
    """A path's parts for `excess_ratio`, rotor by rotor (rotors x 9 x samples: lat and ver
    of Omega_0, Omega_1 and of their derivatives, then the lowest speed `excess_kernel`
    lets the rotor slow to, min(floor, FLOOR_HOVER_SHARE x its hover speed), by the same
    expressions; none of them depends on the duration)."""
    n, n_rot = om0.shape[0], om0.shape[1] // 2
    out = np.empty((n_rot, 9, n))
    for i in range(n_rot):
        for k in range(n):
            out[i, 0, k], out[i, 1, k] = om0[k, 2 * i], om0[k, 2 * i + 1]
            out[i, 2, k], out[i, 3, k] = om1[k, 2 * i], om1[k, 2 * i + 1]
            out[i, 4, k], out[i, 5, k] = dom0[k, 2 * i], dom0[k, 2 * i + 1]
            out[i, 6, k], out[i, 7, k] = dom1[k, 2 * i], dom1[k, 2 * i + 1]
            w0 = math.sqrt(math.sqrt(om0[k, 2 * i] ** 2 + om0[k, 2 * i + 1] ** 2))
            out[i, 8, k] = min(floor, FLOOR_HOVER_SHARE * w0)
    return out


@njit
def _pair_needs(parts: np.ndarray, i: int, u: float, inv_d: float, limit: float,
                tau_up: float, tau_down: float, tilt_limit: float, use_floor: bool,
                out: np.ndarray) -> None:
    """Rotor i's largest need at each sample from its speed, floor, lag, slowing and tilt
    rate (`excess_kernel`'s expressions, without branches: a loop the compiler vectorises)."""
    p = parts[i]
    for k in range(p.shape[1]):
        lat = p[0, k] + u * p[2, k]
        ver = p[1, k] + u * p[3, k]
        dlat = p[4, k] + u * p[6, k]
        dver = p[5, k] + u * p[7, k]
        sq = lat * lat + ver * ver
        w = math.sqrt(math.sqrt(sq))
        moving = sq > TINY
        w_rate = (lat * dlat + ver * dver) / (2.0 * w * sq) * inv_d if moving else 0.0
        tilt_rate = (ver * dlat - lat * dver) / sq * inv_d if moving else 0.0
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


@njit
def excess_ratio(parts: np.ndarray, om0: np.ndarray, om1: np.ndarray, is_end: np.ndarray,
                 duration: float, limit: float, tau_up: float, tau_down: float,
                 tilt_limit: float, step_limit: float, after: np.ndarray, gap: np.ndarray,
                 use_floor: bool, stop: float) -> float:
    """`excess_kernel`'s ratio alone, the same value to the bit (the same candidates from
    the same expressions; their largest does not depend on the order they are met in):
    each rotor's needs (`_pair_needs`, on `pair_parts`), then the tilts' turns to the next
    sample, then the tilt steps at the ends. Returned as soon as it exceeds `stop` (the
    value so far then: enough to tell). A turn takes an atan2 only where its bound (atan t
    <= t, with a margin far above the rounding) could beat the largest need so far."""
    u = 1.0 / (duration * duration)
    inv_d = 1.0 / duration
    n, n_rot = om0.shape[0], om0.shape[1] // 2
    needs = np.empty(n)
    best = -1.0
    for i in range(n_rot):
        _pair_needs(parts, i, u, inv_d, limit, tau_up, tau_down, tilt_limit, use_floor,
                    needs)
        for k in range(n):
            need = float(needs[k])
            if need > best:
                best = need
        if best > stop:
            return best
    for k in range(n):
        j, g = int(after[k]), float(gap[k])
        if j < 0 or not g > 0.0:
            continue
        gd = g * duration
        scale = gd * tilt_limit
        for i in range(n_rot):
            lat = om0[k, 2 * i] + u * om1[k, 2 * i]
            ver = om0[k, 2 * i + 1] + u * om1[k, 2 * i + 1]
            lat_j = om0[j, 2 * i] + u * om1[j, 2 * i]
            ver_j = om0[j, 2 * i + 1] + u * om1[j, 2 * i + 1]
            if not (lat * lat + ver * ver > TINY and lat_j * lat_j + ver_j * ver_j > TINY):
                continue
            y = lat * ver_j - ver * lat_j
            x = lat * lat_j + ver * ver_j
            if x > 0.0:
                room = best * x * scale
                if 1e-290 < room < 1e290 and abs(y) * (1.0 + 1e-9) <= room:
                    continue  # its need is below `best`
            mean_rate = abs(math.atan2(y, x)) / gd
            if mean_rate / tilt_limit > best:
                best = mean_rate / tilt_limit
                if best > stop:
                    return best
    for k in range(n):
        if not is_end[k]:
            continue
        for i in range(n_rot):
            lat = om0[k, 2 * i] + u * om1[k, 2 * i]
            ver = om0[k, 2 * i + 1] + u * om1[k, 2 * i + 1]
            d = math.atan2(lat, ver) - math.atan2(om0[k, 2 * i], om0[k, 2 * i + 1])
            step = abs(math.atan2(math.sin(d), math.cos(d)))
            if step / step_limit > best:
                best = step / step_limit
    return best


@njit
def speed_bound_kernel(om0: np.ndarray, om1: np.ndarray, limit4: float, guard: float
                       ) -> float:
    """`fcu.feasibility.TimeScaling._speed_bound` (rotor speed alone, closed form; its
    numpy expressions element by element, so the same value): w^4 = a u^2 + b u + (c + L^4)
    with u = 1 / D^2, `limit4` = L^4, `guard` its STRETCH_GUARD."""
    n, n_rot = om0.shape[0], om0.shape[1] // 2
    for k in range(n):
        for i in range(n_rot):
            lat0, ver0 = om0[k, 2 * i], om0[k, 2 * i + 1]
            if lat0 * lat0 + ver0 * ver0 - limit4 > 0.0:
                return math.inf
    any_bound = False
    any_nan = False
    u_max = math.inf
    for k in range(n):
        for i in range(n_rot):
            lat0, ver0 = om0[k, 2 * i], om0[k, 2 * i + 1]
            lat1, ver1 = om1[k, 2 * i], om1[k, 2 * i + 1]
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
                return math.inf
            r = num / den
            if r != r:
                any_nan = True
            elif r < u_max:
                u_max = r
    if not any_bound:
        return 0.0
    if any_nan:  # np.min propagates NaN
        u_max = math.nan
    if u_max <= 0.0:
        return math.inf
    return (1.0 + guard) / math.sqrt(u_max)


@njit
def shortest_kernel(parts: np.ndarray, om0: np.ndarray, om1: np.ndarray, dom0: np.ndarray,
                    is_end: np.ndarray, after: np.ndarray, gap: np.ndarray,
                    use_floor: bool, limit: float, limit4: float, tau_up: float,
                    tau_down: float, tilt_limit: float, step_limit: float, guard: float,
                    grid_ratio: float, grid_fits: int, grid_max: int, bisect_tol: float
                    ) -> tuple[float, bool]:
    """`fcu.feasibility.TimeScaling._search` in one call (its steps, in its order, on the
    ratios of `excess_ratio`): (the shortest duration, whether the search found it fitting).
    A failing duration's ratio counts only up to 1e6 there and a bisection's only as fitting
    or not, so `excess_ratio` stops at those."""
    speed_bound = speed_bound_kernel(om0, om1, limit4, guard)
    if not math.isfinite(speed_bound):
        return math.inf, False
    moves = False
    for k in range(om1.shape[0]):
        for c in range(om1.shape[1]):
            if om1[k, c] != 0.0 or dom0[k, c] != 0.0:
                moves = True
    if not moves:  # nothing moves: no rates
        return speed_bound, False
    d = 1e-3 if 1e-3 > speed_bound else speed_bound
    start = d
    last_fail, first_fit, run = math.nan, d, 0
    found = False
    for _ in range(grid_max):
        ratio = excess_ratio(parts, om0, om1, is_end, d, limit, tau_up, tau_down,
                             tilt_limit, step_limit, after, gap, use_floor, 1e6)
        if ratio <= 1.0:
            if run == 0:
                first_fit = d
            run += 1
            if run >= grid_fits:
                found = True
                break
            d *= grid_ratio
        else:
            last_fail, run = d, 0
            grow = (1e6 if 1e6 < ratio else ratio) ** (1.0 / 3.0)
            d *= grow if grow > grid_ratio else grid_ratio
    if not found:
        return math.inf, False
    if math.isnan(last_fail):  # the speed bound (or 1 ms) already fits
        return start, True
    lo, hi = last_fail, first_fit
    while hi - lo > bisect_tol * hi:
        mid = 0.5 * (lo + hi)
        if excess_ratio(parts, om0, om1, is_end, mid, limit, tau_up, tau_down,
                        tilt_limit, step_limit, after, gap, use_floor, 1.0) <= 1.0:
            hi = mid
        else:
            lo = mid
    return hi, True
