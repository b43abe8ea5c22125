"""Can the vehicle fly a planned segment? What the allocation commands along its reference,
judged against every actuator's model (pure: no I/O, no MAVLink).

For a reference r(t) (fcu.control.tracker.Reference: p, q, v, a, omega, omega_dot; ENU / FLU) the
wrench that makes the vehicle follow it exactly (docs/model.md#dynamics with zero tracking error) is

    f_b = m R(q)^T (a - g_W),  g_W = [0, 0, -g];   tau_b = J omega_dot + omega x J omega,

allocated with the pseudo-inverse of eq. (28), Omega = A^+ [f_b; tau_b], each rotor turning at
w_i = (lat_i^2 + ver_i^2)^(1/4) with its tilt at alpha_i = atan2(lat_i, ver_i) (eq. 29,
docs/model.md#geometry). The actuators' models (docs/model.md#plant) limit:

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
too); the lag compensation's tilt lead (fcu.control.allocation.tilt_lead) makes a rate-limited servo
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

Evaluation: the search runs compiled (`fcu.envelope.excess.grid_kernel`, then
`fcu.envelope.excess.bisect_kernel`), each duration judged by `fcu.envelope.excess.fits_kernel`
(whether the largest need of `excess_kernel` is at most 1, to the bit) and a failing one of its grid
measured by `fcu.envelope.excess.excess_ratio` (that largest need, to the bit), on the path's parts
in time order (`fcu.envelope.excess.scaling_parts`, made when first needed: a path asked only
whether a duration fits is judged from its allocations, `fcu.envelope.verdict.fits_raw`, the same
answer); the allocations stay numpy's (a matrix product's rounding depends on its shape, so
each is the one it always was). `TimeScaling` lives in fcu/envelope/scaling.py. The upload
check asks only whether a speed-timed move stretches (`TimeScaling.stretches`: the
bisection stops once the planned duration is outside its bracket), and so does the executor
first, resuming the bisection for a move that stretches. Large allocations are written into
arrays reused once free (`Envelope.scratch`: no page faults of fresh memory). Paths that
depend on the same parameters (`path_key`: a 500-item mission repeats its figures) share
one scaling, and paths that share a part (`Envelope.kept`: a move's
attitudes and poses at rest depend on q0 and phi, not on dp; a figure's shape on its
amplitude and axis, not on its start pose) share that part; `clear_caches` forgets them.

Which items stretch and which are refused is the mission's business (fcu.mission). Actuators
are numbered 1..n as the vehicle file lists its arms (the paper's i = 1..6).
"""

from __future__ import annotations

from collections.abc import Callable
from functools import lru_cache
from typing import Any, TypeVar

import numpy as np

from common.config.scenario import VehicleConfig
from fcu.control.allocation import allocation_matrix, pseudo_inverse
from fcu.control.wrench import _nominal_wrench_rows as _nominal_wrench_rows
from fcu.control.wrench import nominal_wrench as nominal_wrench
from fcu.control.wrench import nominal_wrench_kernel as nominal_wrench_kernel
from fcu.control.wrench import rows, wrench_matrix
from fcu.envelope.excess import ROTOR_DOWN, ROTOR_FLOOR, ROTOR_LAG, TILT, TILT_STEP, Excess
from fcu.envelope.instants import DIFF_STEP as DIFF_STEP
from fcu.envelope.instants import FIGURE_SAMPLES_MAX as FIGURE_SAMPLES_MAX
from fcu.envelope.instants import FIGURE_STEP_RAD as FIGURE_STEP_RAD
from fcu.envelope.instants import MOVE_SAMPLES as MOVE_SAMPLES
from fcu.envelope.instants import MOVE_STEP_RAD as MOVE_STEP_RAD
from fcu.envelope.instants import SampleOrder as SampleOrder
from fcu.envelope.instants import clear_orders, time_order
from fcu.envelope.instants import figure_instants as figure_instants
from fcu.envelope.instants import move_instants as move_instants
from fcu.envelope.kept import Buffers, Kept
from fcu.envelope.scaling import BISECT_TOL as BISECT_TOL
from fcu.envelope.scaling import GRID_FITS as GRID_FITS
from fcu.envelope.scaling import GRID_MAX as GRID_MAX
from fcu.envelope.scaling import GRID_RATIO as GRID_RATIO
from fcu.envelope.scaling import STRETCH_GUARD as STRETCH_GUARD
from fcu.envelope.scaling import TILT_STEP_S as TILT_STEP_S
from fcu.envelope.scaling import Path as Path
from fcu.envelope.scaling import Peak as Peak
from fcu.envelope.scaling import TimeScaling as TimeScaling
from fcu.envelope.scaling import _speeds
from fcu.stages import Reference

MARGIN = 0.85  # share of w_max the feed-forward may use (module docstring)
TILT_MARGIN = 0.75  # share of the tilt servos' rate limit the feed-forward may use
FLOOR = 0.25  # share of w_max below which the feed-forward may not slow a rotor
CACHE_ROWS = 16384  # `Envelope.scaling` keeps the scalings of paths up to this many samples
CACHE_PATHS = 1024  # ... and this many paths
SCRATCH_MIN = 16384  # `Envelope.scratch`: arrays of this many values or more are reused


def at_rest(ref: Reference) -> Reference:
    """The same poses at rest (the part of a path that does not scale with its duration)."""
    zero = (0.0, 0.0, 0.0)
    return ref._replace(v_enu_m_s=zero, a_enu_m_s2=zero, omega_flu_rad_s=zero,
                        omega_dot_flu_rad_s2=zero)




T = TypeVar("T")




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
        self._scalings = Kept(CACHE_ROWS, CACHE_PATHS)
        self._kept = Kept(CACHE_ROWS, CACHE_PATHS)
        self._buffers = Buffers(SCRATCH_MIN, 4, 8)

    def omega_sq(self, ref: Reference) -> np.ndarray:
        """Omega = A^+ [f_b; tau_b] per sample (samples x 2n); a float reference is 1 sample."""
        return np.asarray(self.wrenches(ref) @ self.pinv_t)

    def wrenches(self, ref: Reference) -> np.ndarray:
        """The nominal wrench along `ref` (`nominal_wrench`), a sample's [f_b, tau_b] per
        row (samples x 6, the matrix `omega_sq` allocates); a float reference is 1 row."""
        v = self.vehicle
        parts = (ref.q_enu_flu, ref.a_enu_m_s2, ref.omega_flu_rad_s, ref.omega_dot_flu_rad_s2)
        if all(isinstance(c, float) for p in parts for c in p):
            force, torque = nominal_wrench_kernel(v.mass_kg, v.gravity_m_s2,
                                                  v.inertia_diag_kg_m2, *parts)
            out = np.empty((1, 6))
            out[0, 0], out[0, 1], out[0, 2] = force
            out[0, 3], out[0, 4], out[0, 5] = torque
            return out
        n = max(np.size(c) for p in parts for c in p)
        q, a, w, wd = (rows(p, n) for p in parts)
        out = np.empty((n, 6))
        wrench_matrix(v.mass_kg, v.gravity_m_s2, v.inertia_diag_kg_m2, q, a, w, wd, out)
        return out

    def speeds(self, ref: Reference) -> np.ndarray:
        """Rotor speeds (samples x rotors) of the nominal wrench along `ref`."""
        return _speeds(self.omega_sq(ref))

    def peak(self, ref: Reference) -> Peak:
        per_sample = self.speeds(ref).max(axis=1)
        i = int(np.argmax(per_sample))
        return Peak(float(per_sample[i]), i)

    def allocate(self, wrenches: np.ndarray) -> np.ndarray:
        """Omega = A^+ [f_b; tau_b] of wrench rows (`wrenches`; samples x 2n), a large one
        into a `scratch` array (the same product, to the bit)."""
        pinv_t = self.pinv_t
        if wrenches.shape[0] * pinv_t.shape[1] < SCRATCH_MIN:
            return np.asarray(wrenches @ pinv_t)
        out = self.scratch(wrenches.shape[0], pinv_t.shape[1])
        return np.asarray(np.matmul(wrenches, pinv_t, out=out))

    def scratch(self, rows: int, cols: int) -> np.ndarray:
        """A rows x cols array (values undefined), a large one reused once nothing holds it
        (`fcu.envelope.kept.Buffers`)."""
        return self._buffers.take(rows, cols)

    def kept(self, key: bytes, rows: int, make: Callable[[], T]) -> T:
        """What make() returns, kept by key (`CACHE_ROWS`, `CACHE_PATHS`; `rows`: the samples
        it holds): the parts of a path that other paths share (`scaling`)."""
        hit: T | None = self._kept.get(key)
        if hit is None:
            hit = make()
            self._kept.put(key, hit, rows)
        return hit

    def scaling(self, segment: Path) -> TimeScaling:
        """What the allocation commands along `segment`'s path as a function of the time it
        is flown in: Omega_0, Omega_1 at its instants and their sigma-derivatives. A segment
        with a `path_key` (the bytes of what its 1 s path depends on) shares the scaling of
        an equal one met before (`CACHE_ROWS`, `CACHE_PATHS`); one with a
        `unit_allocations` (the allocations of its 1 s path and of its poses at rest, as
        `omega_sq` makes them from `path`, or None) skips the Reference, and may keep what
        it shares with other paths (`kept`)."""
        key_of = getattr(segment, "path_key", None)
        key: bytes | None = key_of() if key_of is not None else None
        if key is not None:
            hit: TimeScaling | None = self._scalings.get(key)
            if hit is not None:
                return hit
        order = time_order(segment.instants())
        out = TimeScaling(self, None, order, self.allocations(segment, order), segment)
        if key is not None:
            self._scalings.put(key, out, out.samples)
        return out

    def allocations(self, segment: Path, order: SampleOrder) -> tuple[np.ndarray, np.ndarray]:
        """The allocations of `segment`'s 1 s path at the instants `order.stepped` and of its
        poses at rest (`scaling`)."""
        unit_allocations = getattr(segment, "unit_allocations", None)
        pair = unit_allocations(self, order.stepped) if unit_allocations is not None else None
        if pair is None:
            unit = segment.path(order.stepped)
            pair = self.omega_sq(unit), self.omega_sq(at_rest(unit))
        om, hover = pair
        return om, hover

    def clear(self) -> None:
        """Forget the scalings and shared parts kept (`scaling`, `kept`)."""
        self._scalings.clear()
        self._kept.clear()

    def __getstate__(self) -> dict[str, Any]:
        """Pickled without the scalings kept (a plan made in another process carries its
        segments' scalings, not the cache)."""
        state = self.__dict__.copy()
        state["_scalings"] = Kept(CACHE_ROWS, CACHE_PATHS)
        state["_kept"] = Kept(CACHE_ROWS, CACHE_PATHS)
        state["_buffers"] = Buffers(SCRATCH_MIN, 4, 8)
        return state

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


_ENVELOPES: list[Envelope] = []


_LAST: list[tuple[VehicleConfig, float, Envelope]] = []


def envelope(vehicle: VehicleConfig, margin: float = MARGIN) -> Envelope:
    """The (cached) envelope of a vehicle: the pseudo-inverse is computed once. The last
    one given is found by identity first (hashing a VehicleConfig takes microseconds, and
    a mission check asks for it twice an item)."""
    if _LAST and _LAST[0][0] is vehicle and _LAST[0][1] == margin:
        return _LAST[0][2]
    env = _envelope(vehicle, margin)
    _LAST[:] = [(vehicle, margin, env)]
    return env


@lru_cache(maxsize=16)
def _envelope(vehicle: VehicleConfig, margin: float) -> Envelope:
    env = Envelope(vehicle, margin)
    _ENVELOPES.append(env)
    del _ENVELOPES[:-16]
    return env


def clear_caches() -> None:
    """Forget the scalings the envelopes keep (`Envelope.scaling`): each path is evaluated
    afresh (benchmarks time the work, not the cache)."""
    for env in _ENVELOPES:
        env.clear()
    clear_orders()
