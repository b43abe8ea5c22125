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
