"""A path's time scaling (`TimeScaling`): what the allocation commands along a path as a
function of the time it is flown in, and the shortest duration that fits (the search of the
`fcu.envelope.feasibility` docstring); `fcu.envelope.feasibility.Envelope.scaling` makes it."""

from __future__ import annotations

import math
from typing import Any, NamedTuple, Protocol

import numpy as np

from fcu.envelope.excess import (
    KINDS,
    TINY,
    Excess,
    bisect_kernel,
    excess_kernel,
    fits_kernel,
    grid_kernel,
    scaling_parts,
    unpermuted,
)
from fcu.envelope.instants import DIFF_STEP, SampleOrder
from fcu.envelope.speed_bound import speed_bound_kernel
from fcu.envelope.verdict import fits_raw
from fcu.stages import Reference

TILT_STEP_S = 0.05  # a tilt step at a path's end may take the servo this long at its rate
GRID_RATIO = 1.1  # `TimeScaling.shortest`: durations tried from the speed bound up
GRID_FITS = 8  # ... until this many in a row fit (x 2.1 in duration)
GRID_MAX = 1000  # ... at most this many (x 1e41)
BISECT_TOL = 1e-4  # relative: the shortest duration found is at most this much too long
STRETCH_GUARD = 1e-9  # relative: a stretched duration stays this far above the exact bound


def _speeds(omega_sq: np.ndarray) -> np.ndarray:
    """Rotor speeds (samples x rotors) from Omega (samples x [lat_1, ver_1, ...])."""
    lat, ver = omega_sq[:, 0::2], omega_sq[:, 1::2]
    return np.asarray(np.sqrt(np.sqrt(lat * lat + ver * ver)))


class Peak(NamedTuple):
    speed_rad_s: float  # highest rotor speed over the samples
    sample: int  # the index of the sample where it occurs


class Path(Protocol):
    """A segment that can be flown in any duration: its reference flown in 1 s."""

    def path(self, sigma: np.ndarray) -> Reference: ...

    def instants(self) -> np.ndarray: ...


class Envelope(Protocol):
    """What a scaling asks of its envelope (`fcu.envelope.feasibility.Envelope`)."""

    limit: float
    floor: float
    tau_up: float
    tau_down: float
    tilt_limit: float
    tilt_rate_max: float

    def allocations(self, segment: Path, order: SampleOrder
                    ) -> tuple[np.ndarray, np.ndarray]: ...

    def scratch(self, rows: int, cols: int) -> np.ndarray: ...


class TimeScaling:
    """Omega(D) = Omega_0 + Omega_1 / D^2 and its rates at a path's sample instants (module
    docstring), kept as `fcu.envelope.excess.scaling_parts` (the samples in time order: `order`);
    Omega_0, Omega_1 and their derivatives by sample are `om0`, `om1`, `dom0`, `dom1`. Given
    `raw` (the allocations `Envelope.allocations` makes of `path`) instead of the parts, it
    makes them when first asked, and answers `fits` from the allocations until then
    (`fcu.envelope.verdict.fits_raw`), which it forgets once a duration fits (made again from `path`
    where needed)."""

    def __init__(self, env: Envelope, parts: np.ndarray | None, order: SampleOrder,
                 raw: tuple[np.ndarray, np.ndarray] | None = None,
                 path: Path | None = None) -> None:
        self.env, self.limit = env, env.limit
        self._parts, self.order = parts, order
        self._raw, self._path = raw, path
        self.samples = len(order.places)
        self._rows: dict[int, np.ndarray] = {}
        self._shortest: float | None = None
        self._bracket: tuple[float, float] | None = None  # `_search`'s (lo, hi) so far
        self._fit_at: float | None = None  # a duration `_search` found fitting
        self._fits: dict[float, bool] = {}

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state.update(_rows={}, _parts=self.parts, _raw=None, _path=None)  # parts, not path
        return state

    @property
    def parts(self) -> np.ndarray:
        """`fcu.envelope.excess.scaling_parts` of the path (made when first asked)."""
        if self._parts is None:
            om, hover = self._allocations()
            self._parts = scaling_parts(om, hover, self.samples, 2.0 * DIFF_STEP,
                                        self.env.floor, self.order.places,
                                        self.order.place_ends)
            self._raw = self._path = None
        return self._parts

    def _allocations(self) -> tuple[np.ndarray, np.ndarray]:
        if self._raw is not None:
            return self._raw
        assert self._path is not None
        return self.env.allocations(self._path, self.order)

    def _by_sample(self, row: int) -> np.ndarray:
        out = self._rows.get(row)
        if out is None:
            out = self._rows[row] = unpermuted(self.parts, row, self.order.place_of)
        return out

    @property
    def om0(self) -> np.ndarray:
        return self._by_sample(0)

    @property
    def om1(self) -> np.ndarray:
        return self._by_sample(2)

    @property
    def dom0(self) -> np.ndarray:
        return self._by_sample(4)

    @property
    def dom1(self) -> np.ndarray:
        return self._by_sample(6)

    @property
    def after(self) -> np.ndarray:
        """The index of the next sample in time, -1 for none (`excess_kernel`)."""
        return self.order.after

    @property
    def gap(self) -> np.ndarray:
        """The normalised time to it (`excess_kernel`)."""
        return self.order.gap

    @property
    def is_end(self) -> np.ndarray:
        out = np.zeros(self.samples, dtype=np.bool_)
        out[self.order.ends] = True
        return out

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
        """excess(duration).ratio <= 1 (`excess_ratio`, stopping at the first need beyond)."""
        duration = float(duration)
        if duration == self._fit_at:
            return True
        hit = self._fits.get(duration)
        if hit is None:
            env, o = self.env, self.order
            limits = (duration, env.limit, env.tau_up, env.tau_down, env.tilt_limit,
                      env.tilt_rate_max * TILT_STEP_S, env.floor > 0.0)
            if self._parts is None:
                om, hover = self._allocations()
                room = env.scratch(om.shape[1] * 5, self.samples)  # rotors x 10 rows
                hit = fits_raw(om, hover, 2.0 * DIFF_STEP, env.floor, o.places, o.place_gap,
                               o.place_ends, *limits, room)
                if hit and self._path is not None:
                    self._raw = None  # made again from the path if the parts are asked
            else:
                hit = fits_kernel(self._parts, o.place_gap, o.place_ends, *limits,
                                  np.empty(self.samples))
            if len(self._fits) < 16:
                self._fits[duration] = hit
        return hit

    def shortest(self) -> float:
        """The shortest duration D such that the path flown in D or any longer time keeps
        every actuator within its limit (module docstring); 0 when any duration does, inf
        when none does (hovering at some attitude of the path already exceeds the limit)."""
        if self._shortest is None:
            self._search(math.nan)
        assert self._shortest is not None
        return self._shortest

    def stretches(self, duration: float) -> bool:
        """math.isfinite(shortest()) and shortest() > duration, the same answer, with the
        search's bisection taken only until `duration` lies outside its bracket (the rest
        when `shortest` is asked)."""
        bracket = self._bracket
        if self._shortest is None and (bracket is None or bracket[0] <= duration < bracket[1]):
            self._search(float(duration))
        if self._shortest is not None:
            return math.isfinite(self._shortest) and self._shortest > duration
        assert self._bracket is not None
        return duration < self._bracket[0]  # the bisection ends above lo, at hi or below

    def searched(self, lo: float, hi: float, shortest: float, fit_at: float) -> None:
        """The state `_search` leaves, given by a search made elsewhere with the same kernels
        (`fcu.mission.stretch`): its bracket (lo, hi), the shortest duration once it ended and
        a duration it found fitting (NaN: none yet)."""
        self._bracket = lo, hi
        self._shortest = None if math.isnan(shortest) else shortest
        self._fit_at = None if math.isnan(fit_at) else fit_at

    def knows(self, duration: float, fits: bool) -> None:
        """`fits(duration)`, judged elsewhere by the same kernel (`fcu.mission.stretch`)."""
        if len(self._fits) < 16:
            self._fits[float(duration)] = fits

    def _search(self, until: float) -> None:
        """From the speed bound up: while a duration fails by a ratio r, the next tried is
        r^(1/3) longer (no need decays faster than 1/D^3: accelerations scale by 1/D^2 and
        rates take another 1/D, so this never jumps past the bound), at least GRID_RATIO;
        GRID_FITS fitting durations in a row end the search, then bisection between the
        last failing and the first fitting one (`fcu.envelope.excess.grid_kernel`,
        `fcu.envelope.excess.bisect_kernel`), until it ends or `until` lies outside its bracket."""
        env = self.env
        checks = (self.parts, self.order.place_gap, self.order.place_ends, env.floor > 0.0)
        if self._bracket is None:
            lo, hi, fitted = grid_kernel(
                *checks, env.limit, env.limit ** 4, env.tau_up, env.tau_down, env.tilt_limit,
                env.tilt_rate_max * TILT_STEP_S, STRETCH_GUARD, GRID_RATIO, GRID_FITS,
                GRID_MAX)
            self._bracket = lo, hi
            if math.isnan(lo):
                self._shortest = hi
                if fitted:
                    self._fit_at = hi
                return
        lo, hi = self._bracket
        if until != until or lo <= until < hi:  # else the bisection takes no step
            lo, hi = bisect_kernel(*checks, env.limit, env.tau_up, env.tau_down,
                                   env.tilt_limit, env.tilt_rate_max * TILT_STEP_S, lo, hi,
                                   BISECT_TOL, until)
        self._bracket = lo, hi
        if not hi - lo > BISECT_TOL * hi:
            self._shortest = self._fit_at = hi

    def _speed_bound(self) -> float:
        """Rotor speed alone (no lag): the closed form of the module docstring
        (`fcu.envelope.speed_bound.speed_bound_kernel`)."""
        return speed_bound_kernel(self.parts, self.limit ** 4, STRETCH_GUARD)
