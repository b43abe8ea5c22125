"""Can the vehicle fly a planned segment? What the allocation commands along its reference,
judged against every actuator's model (pure: no I/O, no MAVLink).

For a reference r(t) (fcu.tracker.Reference: p, q, v, a, omega, omega_dot; ENU / FLU) the
wrench that makes the vehicle follow it exactly (MODEL.md section 4 with zero tracking error) is

    f_b = m R(q)^T (a - g_W),  g_W = [0, 0, -g];   tau_b = J omega_dot + omega x J omega,

allocated with the pseudo-inverse of eq. (28), Omega = A^+ [f_b; tau_b], each rotor turning at
w_i = (lat_i^2 + ver_i^2)^(1/4) with its tilt at alpha_i = atan2(lat_i, ver_i) (eq. 29,
MODEL.md section 2). The actuators' models (MODEL.md 2, as the plant has them) limit:

* rotor speed, with its first-order lag: the command that makes a lagging rotor follow w_i,
  c_i = w_i + tau_up w_i' while it speeds up, must stay at most MARGIN w_max, and one that
  slows down, w_i - tau_down |w_i'|, at least 0 (`Actuator` "rotor");
* tilt servo rate: |alpha_i'| <= TILT_MARGIN tilt_rate_max (tilts are continuous and
  unbounded, so only their rate is limited; "tilt servo"), and where a path starts from or
  ends at rest with an acceleration (a figure-infinity), the tilt step there within what the
  servo turns in TILT_STEP_S ("tilt step").

FLOOR = 0.25: no rotor may be slowed below 25 % of its speed limit (`ROTOR_FLOOR`; 6 % of its
thrust, 15-18 % of what it takes in level hover on the presets), so that the feedback can
still lower a thrust without reversing it: a climb on planar rotors may then brake, and a
descent start, at about 0.8 g (at 0.93 g, the floor at 15 %, a 0.3 m descent at 1.3 m/s
flipped every servo on the planar preset). Where hovering at a path's attitude already
takes a rotor below that (333 rad/s on the planar preset at some attitudes of a figure),
the floor there is 80 % of that hover speed (`FLOOR_HOVER_SHARE`). A reversal itself, where
a rotor's thrust passes through zero and its tilt turns half a
revolution between two samples, is caught by each tilt's mean rate from one sample to the
next (`excess_kernel`).

MARGIN = 0.85: the feed-forward may use at most 85 % of the rotor speed limit (72 % of the
thrust), leaving the rest for the feedback that corrects tracking errors, disturbances and the
rotor lag on top of it. It cannot be much lower: hovering at the worst attitude takes 1215 rad/s
(71 %) on the tilted preset and 1402 rad/s (82 %) on the planar one, so a lower margin would
refuse attitudes the vehicle holds. TILT_MARGIN = 0.75: the feed-forward may turn a tilt at
three quarters of the servo's rate, the rest is the feedback's (its corrections move the tilts
too); the lag compensation's tilt lead (fcu.allocation.tilt_lead) makes a rate-limited servo
follow a ramp below its limit without lag.

Time scaling: flying a fixed path (position and attitude as functions of sigma = t / D) in D
seconds scales velocities and body rates by 1/D and accelerations, omega_dot and omega x J omega
by 1/D^2, so with u = 1/D^2

    Omega(D) = Omega_0 + u Omega_1   (Omega_0: hover at the path's attitudes),

exactly, and d/dt = (1/D) d/dsigma: with Omega' = Omega_0' + u Omega_1' (sigma-derivatives,
central differences of the 1 s path),

    alpha_i' = (ver_i lat_i' - lat_i ver_i') / (lat_i^2 + ver_i^2) / D
    w_i'     = (lat_i lat_i' + ver_i ver_i') / (2 w_i^3) / D.

Rotor speed alone gives w_i^4 = |Omega_0,i + u Omega_1,i|^2, a quadratic in u whose bound comes
in closed form; the rates add no closed form, so the shortest duration that fits at that and
every longer duration is found from that bound up on a geometric grid, then by bisection
(`TimeScaling.shortest`).

Sampling: `MOVE_SAMPLES` evenly spaced instants of a quintic move including both ends (more for
a move that turns: at most `MOVE_STEP_RAD` of attitude apart), plus the
instants of its extreme acceleration (s = 0.5 -/+ sqrt(3)/6) and of its top speed (s = 0.5);
for the figure-infinity, evenly spaced instants with a step of at most `FIGURE_STEP_RAD` of
attitude (T |n|) and of the path phase 2T (at least `MOVE_SAMPLES`, at most `FIGURE_SAMPLES_MAX`),
plus its ends (extreme T''), its middle (top T') and the phases T = j pi / 4 where the path's
coordinates peak.

Which items stretch and which are refused is the mission's business (fcu.mission). Actuators
are numbered 1..n as the vehicle file lists its arms (the paper's i = 1..6).
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import Any, NamedTuple, Protocol

import numpy as np

from common.config import VehicleConfig
from common.jit import njit
from fcu.allocation import allocation_matrix, pseudo_inverse
from fcu.dualquat import Quat, Vec3, cross, q_rotate_inv
from fcu.excess import (
    KINDS,
    ROTOR_DOWN,
    ROTOR_FLOOR,
    ROTOR_LAG,
    TILT,
    TILT_STEP,
    TINY,
    Excess,
    excess_kernel,
)
from fcu.tracker import Reference

MARGIN = 0.85  # share of w_max the feed-forward may use (module docstring)
TILT_MARGIN = 0.75  # share of the tilt servos' rate limit the feed-forward may use
FLOOR = 0.25  # share of w_max below which the feed-forward may not slow a rotor
TILT_STEP_S = 0.05  # a tilt step at a path's end may take the servo this long at its rate
DIFF_STEP = 1e-6  # sigma step of the central differences of a 1 s path
GRID_RATIO = 1.1  # `TimeScaling.shortest`: durations tried from the speed bound up
GRID_FITS = 8  # ... until this many in a row fit (x 2.1 in duration)
GRID_MAX = 1000  # ... at most this many (x 1e41)
BISECT_TOL = 1e-4  # relative: the shortest duration found is at most this much too long
MOVE_SAMPLES = 64
FIGURE_STEP_RAD = 0.02  # rad of attitude and phase between a figure's samples
MOVE_STEP_RAD = 0.01  # rad of attitude between a turning move's samples
FIGURE_SAMPLES_MAX = 4096
STRETCH_GUARD = 1e-9  # relative: a stretched duration stays this far above the exact bound

_QUINTIC_PEAKS = (0.5 - math.sqrt(3.0) / 6.0, 0.5, 0.5 + math.sqrt(3.0) / 6.0)


class Path(Protocol):
    """A segment that can be flown in any duration: its reference flown in 1 s."""

    def path(self, sigma: np.ndarray) -> Reference: ...

    def instants(self) -> np.ndarray: ...


_MOVE_INSTANTS = np.concatenate([np.linspace(0.0, 1.0, MOVE_SAMPLES), _QUINTIC_PEAKS])
_MOVE_INSTANTS.flags.writeable = False


@lru_cache(maxsize=64)
def _turning_instants(n: int) -> np.ndarray:
    out = np.concatenate([np.linspace(0.0, 1.0, n), _QUINTIC_PEAKS])
    out.flags.writeable = False
    return out


def move_instants(turn_rad: float = 0.0) -> np.ndarray:
    """Normalised check instants of a quintic move that turns `turn_rad` (module docstring;
    read-only): a tilt can swing fast where a rotor's thrust passes near zero as the body
    turns, so a turning move is sampled at most MOVE_STEP_RAD of attitude apart."""
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


@njit
def nominal_wrench_kernel(m: float, g: float, inertia: Vec3, q: Quat, a: Vec3, w: Vec3,
                          wd: Vec3) -> tuple[Vec3, Vec3]:
    """(f_b, tau_b) that follow a reference exactly: m R^T (a - g_W), J omega' + omega x J
    omega, for its attitude q, acceleration a, rate w and rate derivative wd."""
    force = q_rotate_inv(q, (m * a[0], m * a[1], m * (a[2] + g)))
    jx, jy, jz = inertia[0], inertia[1], inertia[2]
    gyro = cross(w, (jx * w[0], jy * w[1], jz * w[2]))
    return force, (jx * wd[0] + gyro[0], jy * wd[1] + gyro[1], jz * wd[2] + gyro[2])


@njit
def _nominal_wrench_rows(m: float, g: float, inertia: Vec3, q: np.ndarray, a: np.ndarray,
                         w: np.ndarray, wd: np.ndarray) -> np.ndarray:
    """nominal_wrench_kernel per sample: columns of q (4 x n), a, w, wd (3 x n) -> 6 x n."""
    n = q.shape[1]
    out = np.empty((6, n))
    for i in range(n):
        f, t = nominal_wrench_kernel(m, g, inertia, (q[0, i], q[1, i], q[2, i], q[3, i]),
                                     (a[0, i], a[1, i], a[2, i]), (w[0, i], w[1, i], w[2, i]),
                                     (wd[0, i], wd[1, i], wd[2, i]))
        out[0, i], out[1, i], out[2, i] = f
        out[3, i], out[4, i], out[5, i] = t
    return out


def nominal_wrench(vehicle: VehicleConfig, ref: Reference) -> tuple[Vec3, Vec3]:
    """(f_b, tau_b) that follow `ref` exactly: m R^T (a - g_W), J omega' + omega x J omega.

    Fields may be floats or numpy arrays (many samples at once: the result's parts are then
    arrays)."""
    m, g, inertia = vehicle.mass_kg, vehicle.gravity_m_s2, vehicle.inertia_diag_kg_m2
    parts = (ref.q_enu_flu, ref.a_enu_m_s2, ref.omega_flu_rad_s, ref.omega_dot_flu_rad_s2)
    if all(isinstance(c, float) for p in parts for c in p):
        return nominal_wrench_kernel(m, g, inertia, *parts)
    n = max(np.size(c) for p in parts for c in p)
    q, a, w, wd = (np.array([np.broadcast_to(np.asarray(c, dtype=np.float64), (n,))
                             for c in p]) for p in parts)
    rows = _nominal_wrench_rows(m, g, inertia, q, a, w, wd)
    return (rows[0], rows[1], rows[2]), (rows[3], rows[4], rows[5])


def _hover(ref: Reference) -> Reference:
    """The same poses at rest (the part of a path that does not scale with its duration)."""
    zero = (0.0, 0.0, 0.0)
    return ref._replace(v_enu_m_s=zero, a_enu_m_s2=zero, omega_flu_rad_s=zero,
                        omega_dot_flu_rad_s2=zero)


def _speeds(omega_sq: np.ndarray) -> np.ndarray:
    """Rotor speeds (samples x rotors) from Omega (samples x [lat_1, ver_1, ...])."""
    lat, ver = omega_sq[:, 0::2], omega_sq[:, 1::2]
    return np.asarray(np.sqrt(np.sqrt(lat * lat + ver * ver)))


class Peak(NamedTuple):
    speed_rad_s: float  # highest rotor speed over the samples
    sample: int  # the index of the sample where it occurs


class Envelope:
    """One vehicle's actuator limits for feed-forward commands (module docstring): rotor
    speed `margin` w_max with its lag, tilt rate TILT_MARGIN tilt_rate_max."""

    def __init__(self, vehicle: VehicleConfig, margin: float = MARGIN,
                 tilt_margin: float = TILT_MARGIN) -> None:
        if not 0.0 < margin <= 1.0 or not 0.0 < tilt_margin <= 1.0:
            raise ValueError(f"margins must be in (0, 1], got {margin}, {tilt_margin}")
        self.vehicle = vehicle
        self.margin = margin
        self.speed_max = vehicle.rotor_speed_max_rad_s
        self.limit = margin * self.speed_max
        self.floor = FLOOR * self.speed_max
        self.tilt_margin = tilt_margin
        self.tilt_rate_max = vehicle.tilt_rate_max_rad_s
        self.tilt_limit = tilt_margin * self.tilt_rate_max
        self.tau_up, self.tau_down = vehicle.rotor_tau_up_s, vehicle.rotor_tau_down_s
        self.pinv_t = pseudo_inverse(allocation_matrix(vehicle)).T  # 6 x 2n

    def omega_sq(self, ref: Reference) -> np.ndarray:
        """Omega = A^+ [f_b; tau_b] per sample (samples x 2n); a float reference is 1 sample."""
        return self._allocate(*nominal_wrench(self.vehicle, ref))

    def _allocate(self, force: Any, torque: Any) -> np.ndarray:
        parts = (*force, *torque)
        wrench = np.empty((max(np.size(c) for c in parts), 6))
        for k, c in enumerate(parts):
            wrench[:, k] = c
        return np.asarray(wrench @ self.pinv_t)

    def speeds(self, ref: Reference) -> np.ndarray:
        """Rotor speeds (samples x rotors) of the nominal wrench along `ref`."""
        return _speeds(self.omega_sq(ref))

    def peak(self, ref: Reference) -> Peak:
        per_sample = self.speeds(ref).max(axis=1)
        i = int(np.argmax(per_sample))
        return Peak(float(per_sample[i]), i)

    def scaling(self, segment: Path) -> TimeScaling:
        """What the allocation commands along `segment`'s path as a function of the time it
        is flown in: Omega_0, Omega_1 at its instants and their sigma-derivatives."""
        sigma = segment.instants()
        n = len(sigma)
        unit = segment.path(np.concatenate([sigma, sigma - DIFF_STEP, sigma + DIFF_STEP]))
        om_all = self.omega_sq(unit)
        om0_all = np.broadcast_to(self.omega_sq(_hover(unit)), om_all.shape)
        om1_all = om_all - om0_all
        om0, lo0, hi0 = om0_all[:n], om0_all[n:2 * n], om0_all[2 * n:]
        om1, lo1, hi1 = om1_all[:n], om1_all[n:2 * n], om1_all[2 * n:]
        h2 = 2.0 * DIFF_STEP
        ends = np.flatnonzero((sigma == 0.0) | (sigma == 1.0))
        order = np.argsort(sigma, kind="stable")
        after = np.full(n, -1, dtype=np.int64)
        after[order[:-1]] = order[1:]
        gap = np.where(after >= 0, sigma[after] - sigma, 0.0)
        return TimeScaling(self, om0, om1, (hi0 - lo0) / h2, (hi1 - lo1) / h2, ends,
                           after, gap)

    def describe(self, speed_rad_s: float) -> str:
        return (f"needs {speed_rad_s:.0f} rad/s > {self.limit:.0f} "
                f"({self.margin * 100:.0f}% of {self.speed_max:.0f})")

    def explain(self, excess: Excess) -> str:
        """`excess` for a person: "tilt servo 2 needs 13.1 rad/s, limit 2.0 (50% of 4.0)"."""
        if excess.kind == TILT:
            return (f"tilt servo {excess.number} needs {excess.need:.1f} rad/s, limit "
                    f"{excess.limit:.1f} ({self.tilt_margin * 100:.0f}% of "
                    f"{self.tilt_rate_max:.1f})")
        if excess.kind == TILT_STEP:
            return (f"tilt servo {excess.number} steps {excess.need:.2f} rad at a start or end, "
                    f"limit {excess.limit:.2f} ({TILT_STEP_S * 1e3:.0f} ms at "
                    f"{self.tilt_rate_max:.1f} rad/s)")
        if excess.kind == ROTOR_FLOOR:
            return (f"rotor {excess.number} slows to {excess.need:.0f} rad/s, floor "
                    f"{excess.limit:.0f} ({FLOOR * 100:.0f}% of {self.speed_max:.0f}: its "
                    "thrust would near zero or reverse)")
        if excess.kind == ROTOR_DOWN:
            return (f"rotor {excess.number} must slow at {excess.need:.0f} rad/s^2, its lag "
                    f"allows {excess.limit:.0f}")
        return (f"rotor {excess.number} needs {excess.need:.0f} rad/s, limit "
                f"{excess.limit:.0f} ({self.margin * 100:.0f}% of {self.speed_max:.0f})"
                + (" with its lag" if excess.kind == ROTOR_LAG else ""))


class TimeScaling:
    """Omega(D) = Omega_0 + Omega_1 / D^2 and its rates at a path's sample instants (module
    docstring)."""

    def __init__(self, env: Envelope, om0: np.ndarray, om1: np.ndarray, dom0: np.ndarray,
                 dom1: np.ndarray, ends: np.ndarray | None = None,
                 after: np.ndarray | None = None, gap: np.ndarray | None = None) -> None:
        self.env, self.limit = env, env.limit
        self.om0, self.om1, self.dom0, self.dom1 = (np.ascontiguousarray(x, dtype=np.float64)
                                                    for x in (om0, om1, dom0, dom1))
        self.is_end = np.zeros(len(om0), dtype=np.bool_)
        if ends is not None:
            self.is_end[ends] = True
        n = len(om0)
        # the next sample in time and the normalised time to it (`excess_kernel`)
        self.after = np.full(n, -1, dtype=np.int64) if after is None else \
            np.ascontiguousarray(after, dtype=np.int64)
        self.gap = np.zeros(n) if gap is None else np.ascontiguousarray(gap, dtype=np.float64)
        self._shortest: float | None = None

    def _omega(self, duration: float) -> tuple[np.ndarray, np.ndarray]:
        u = 1.0 / (duration * duration) if duration > 0.0 else math.inf
        return self.om0 + u * self.om1, self.dom0 + u * self.dom1

    def speeds(self, duration: float) -> np.ndarray:
        return _speeds(self._omega(duration)[0])

    def peak(self, duration: float) -> Peak:
        per_sample = self.speeds(duration).max(axis=1)
        i = int(np.argmax(per_sample))
        return Peak(float(per_sample[i]), i)

    def rates(self, duration: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rotor speeds, their rates and the tilt rates (samples x rotors) of the path flown
        in `duration` s."""
        om, dom = self._omega(duration)
        lat, ver, dlat, dver = om[:, 0::2], om[:, 1::2], dom[:, 0::2], dom[:, 1::2]
        sq = lat * lat + ver * ver
        w = np.sqrt(np.sqrt(sq))
        with np.errstate(divide="ignore", invalid="ignore"):
            w_rate = np.where(sq > TINY, (lat * dlat + ver * dver) / (2.0 * w * sq), 0.0)
            tilt_rate = np.where(sq > TINY, (ver * dlat - lat * dver) / sq, 0.0)
        return w, w_rate / duration, tilt_rate / duration

    def excess(self, duration: float) -> Excess:
        """The most demanding actuator of the path flown in `duration` s (module docstring;
        `excess_kernel`)."""
        env = self.env
        ratio, kind, rotor, sample, need, limit = excess_kernel(
            self.om0, self.om1, self.dom0, self.dom1, self.is_end, float(duration), env.limit,
            env.tau_up, env.tau_down, env.tilt_limit, env.tilt_rate_max * TILT_STEP_S,
            self.after, self.gap, env.floor)
        return Excess(ratio, KINDS[kind], rotor + 1, need, limit, sample)

    def fits(self, duration: float) -> bool:
        return self.excess(duration).ratio <= 1.0

    def shortest(self) -> float:
        """The shortest duration D such that the path flown in D or any longer time keeps
        every actuator within its limit (module docstring); 0 when any duration does, inf
        when none does (hovering at some attitude of the path already exceeds the limit)."""
        if self._shortest is None:
            self._shortest = self._search()
        return self._shortest

    def _search(self) -> float:
        """From the speed bound up: while a duration fails by a ratio r, the next tried is
        r^(1/3) longer (no need decays faster than 1/D^3: accelerations scale by 1/D^2 and
        rates take another 1/D, so this never jumps past the bound), at least GRID_RATIO;
        GRID_FITS fitting durations in a row end the search, then bisection between the
        last failing and the first fitting one."""
        speed_bound = self._speed_bound()
        if not math.isfinite(speed_bound):
            return math.inf
        if not np.any(self.om1) and not np.any(self.dom0):
            return speed_bound  # nothing moves: no rates
        start = d = max(speed_bound, 1e-3)
        last_fail, first_fit, run = math.nan, d, 0
        for _ in range(GRID_MAX):
            ratio = self.excess(d).ratio
            if ratio <= 1.0:
                first_fit = d if run == 0 else first_fit
                run += 1
                if run >= GRID_FITS:
                    break
                d *= GRID_RATIO
            else:
                last_fail, run = d, 0
                d *= max(GRID_RATIO, min(ratio, 1e6) ** (1.0 / 3.0))
        else:
            return math.inf
        if math.isnan(last_fail):  # the speed bound (or 1 ms) already fits
            return start
        return self._refine(last_fail, first_fit)

    def _refine(self, lo: float, hi: float) -> float:
        """Bisection between a failing `lo` and a fitting `hi`, to BISECT_TOL of hi."""
        while hi - lo > BISECT_TOL * hi:
            mid = 0.5 * (lo + hi)
            if self.fits(mid):
                hi = mid
            else:
                lo = mid
        return hi

    def _speed_bound(self) -> float:
        """Rotor speed alone (no lag): the closed form of the module docstring."""
        lat0, ver0 = self.om0[:, 0::2], self.om0[:, 1::2]
        lat1, ver1 = self.om1[:, 0::2], self.om1[:, 1::2]
        # w^4 = a u^2 + b u + (c + L^4) with u = 1 / D^2 >= 0.
        a = lat1 * lat1 + ver1 * ver1
        b = 2.0 * (lat0 * lat1 + ver0 * ver1)
        c = lat0 * lat0 + ver0 * ver0 - self.limit ** 4
        if np.any(c > 0.0):
            return math.inf
        # c <= 0: w^4 <= L^4 on [0, u_hi], u_hi the larger root, unbounded where nothing
        # moves (a = 0), in the form without cancellation: (sq - b) / 2a = -2c / (b + sq).
        bound = a > 0.0
        if not np.any(bound):
            return 0.0
        a, b, c = a[bound], b[bound], c[bound]
        sq = np.sqrt(np.maximum(b * b - 4.0 * a * c, 0.0))
        num = np.where(b < 0.0, sq - b, -2.0 * c)
        den = np.where(b < 0.0, 2.0 * a, b + sq)
        if np.any(den <= 0.0):  # b = c = 0: at the limit in hover, any motion exceeds it
            return math.inf
        u_max = float(np.min(num / den))
        if u_max <= 0.0:
            return math.inf
        return (1.0 + STRETCH_GUARD) / math.sqrt(u_max)


@lru_cache(maxsize=16)
def envelope(vehicle: VehicleConfig, margin: float = MARGIN) -> Envelope:
    """The (cached) envelope of a vehicle: the pseudo-inverse is computed once."""
    return Envelope(vehicle, margin)
