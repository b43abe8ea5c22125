"""The gyro's low-pass filter before the controller (PX4's IMU_GYRO_CUTOFF).

A second-order Butterworth filter per axis (PX4's LowPassFilter2p: the bilinear transform
with the cut-off pre-warped), run on every IMU sample; the controller's damping terms take
the filtered, bias-corrected rate. Pure: the sample rate and the cut-off are given.
"""

from __future__ import annotations

import math

import numpy as np

from common.jit import compiled_for, njit
from common.quaternion import q_normalize
from common.warm_ups import warm_up
from fcu.estimator.buffers import filter_buffers
from fcu.estimator.ekf import Estimator
from fcu.estimator.readout import output_values
from fcu.estimator.settings import EstimatorSettings
from fcu.stages import VehicleState

Vec3 = tuple[float, float, float]


class GyroLowPass:
    """y = LPF2(x) per axis at `sample_hz`, cut-off `cutoff_hz` (0: pass through)."""

    def __init__(self, sample_hz: float, cutoff_hz: float) -> None:
        if not (math.isfinite(sample_hz) and sample_hz > 0.0):
            raise ValueError(f"sample rate must be > 0, got {sample_hz!r}")
        if not (math.isfinite(cutoff_hz) and cutoff_hz >= 0.0):
            raise ValueError(f"cut-off must be >= 0, got {cutoff_hz!r}")
        self.sample_hz = sample_hz
        self.cutoff_hz = cutoff_hz
        self.active = 0.0 < cutoff_hz < 0.5 * sample_hz
        fr = sample_hz / cutoff_hz if self.active else 1.0
        ohm = math.tan(math.pi / fr)
        c = 1.0 + 2.0 * math.cos(math.pi / 4.0) * ohm + ohm * ohm
        self.b0 = ohm * ohm / c
        self.b1 = 2.0 * self.b0
        self.b2 = self.b0
        self.a1 = 2.0 * (ohm * ohm - 1.0) / c
        self.a2 = (1.0 - 2.0 * math.cos(math.pi / 4.0) * ohm + ohm * ohm) / c
        self._d1 = [0.0, 0.0, 0.0]
        self._d2 = [0.0, 0.0, 0.0]
        self._started = False
        self.output: Vec3 = (0.0, 0.0, 0.0)

    def reset(self, x: Vec3) -> None:
        """Start at rest on x (the filter's steady state for a constant input)."""
        for i in range(3):
            d = x[i] / (1.0 + self.a1 + self.a2)
            self._d1[i] = d
            self._d2[i] = d
        self.output = x
        self._started = True

    def update(self, x: Vec3) -> Vec3:
        """One sample in, the filtered rate out; a non-finite sample is held out."""
        x0, x1, x2 = x
        isfinite = math.isfinite
        if not (isfinite(x0) and isfinite(x1) and isfinite(x2)):
            return self.output
        if not self.active:
            self.output = x
            return x
        if not self._started:
            self.reset(x)
            return x
        a1, a2, b0, b1, b2 = self.a1, self.a2, self.b0, self.b1, self.b2
        d1, d2 = self._d1, self._d2
        e0 = x0 - d1[0] * a1 - d2[0] * a2
        e1 = x1 - d1[1] * a1 - d2[1] * a2
        e2 = x2 - d1[2] * a1 - d2[2] * a2
        self.output = (e0 * b0 + d1[0] * b1 + d2[0] * b2, e1 * b0 + d1[1] * b1 + d2[1] * b2,
                       e2 * b0 + d1[2] * b1 + d2[2] * b2)
        self._d2 = d1
        self._d1 = [e0, e1, e2]
        return self.output


# ImuRateFilter's state, one array for its compiled sample (`rate_filter_step`)
RF_CUTOFF = 0  # IMU_GYRO_CUTOFF, Hz (0: off)
RF_BUILT = 1  # 1: the low-pass is built (at the IMU's rate, from the first two samples)
RF_ACTIVE = 2  # 1: it filters (GyroLowPass.active)
RF_STARTED = 3  # 1: started at rest on its first sample
RF_COEF = 4  # 5: a1, a2, b0, b1, b2
RF_D1 = 9  # 3: the delay line, newest
RF_D2 = 12  # 3: and the one before
RF_OUT = 15  # 3: the filtered rate
RF_HAS_LAST = 18  # 1: a finite sample was seen
RF_LAST_T = 19  # its time, us
RF_LAST_W = 20  # 3: its rate
RF_SIZE = 23


@njit
def rate_filter_step(st: np.ndarray, t_us: int, w0: float, w1: float, w2: float) -> bool:
    """One gyro sample through `ImuRateFilter.update`'s rules (`GyroLowPass.update`'s
    arithmetic in its order); True: the low-pass must be built first, at the interval since
    the last sample (RF_LAST_T), nothing done yet (build it, then call again)."""
    if not (math.isfinite(w0) and math.isfinite(w1) and math.isfinite(w2)):
        return False
    if st[RF_BUILT] == 0.0:
        if st[RF_HAS_LAST] != 0.0 and st[RF_CUTOFF] != 0.0 and t_us > st[RF_LAST_T]:
            return True
    st[RF_HAS_LAST], st[RF_LAST_T] = 1.0, t_us
    st[RF_LAST_W], st[RF_LAST_W + 1], st[RF_LAST_W + 2] = w0, w1, w2
    if st[RF_BUILT] == 0.0:
        return False
    if st[RF_ACTIVE] == 0.0 or st[RF_STARTED] == 0.0:  # pass through, or start at rest
        if st[RF_ACTIVE] != 0.0:
            den = 1.0 + st[RF_COEF] + st[RF_COEF + 1]
            st[RF_D1], st[RF_D1 + 1], st[RF_D1 + 2] = w0 / den, w1 / den, w2 / den
            st[RF_D2:RF_D2 + 3] = st[RF_D1:RF_D1 + 3]
            st[RF_STARTED] = 1.0
        st[RF_OUT], st[RF_OUT + 1], st[RF_OUT + 2] = w0, w1, w2
        return False
    a1, a2, b0, b1, b2 = (st[RF_COEF], st[RF_COEF + 1], st[RF_COEF + 2], st[RF_COEF + 3],
                          st[RF_COEF + 4])
    x = (w0, w1, w2)
    for i in range(3):
        d1, d2 = st[RF_D1 + i], st[RF_D2 + i]
        e = x[i] - d1 * a1 - d2 * a2
        st[RF_OUT + i] = e * b0 + d1 * b1 + d2 * b2
        st[RF_D2 + i], st[RF_D1 + i] = d1, e
    return False


class ImuRateFilter:
    """IMU_GYRO_CUTOFF on the estimator's rate: every finite gyro sample goes through a
    GyroLowPass built at the IMU's own rate (from the first two samples), one compiled call
    a sample (`rate_filter_step`, its state in one array); `apply` gives a state whose
    rate is the newest sample less the bias (the estimator's output) the filtered rate
    less the same bias. The pipeline and a log replay share it."""

    def __init__(self, cutoff_hz: float) -> None:
        self.cutoff_hz = cutoff_hz
        self.st = np.zeros(RF_SIZE)
        self.st[RF_CUTOFF] = cutoff_hz
        warm_up("fcu.control.rate_filter", _warm_up)
        # the kernels' machine code for these types (`compiled_for`); the estimator's
        # buffers are those `filter_buffers` makes
        self._step = compiled_for(rate_filter_step, self.st, 0, 0.0, 0.0, 0.0)
        self._flown = compiled_for(flown_values, *filter_buffers(EstimatorSettings())[:2],
                                   self.st)

    def update(self, t_us: int, w: Vec3) -> None:
        st = self.st
        if type(t_us) is not int:
            t_us = int(t_us)
        if self._step(st, t_us, w[0], w[1], w[2]):
            # the low-pass's coefficients (its state lives in the array)
            lpf = GyroLowPass(1e6 / (t_us - int(st[RF_LAST_T])), self.cutoff_hz)
            st[RF_COEF:RF_COEF + 5] = (lpf.a1, lpf.a2, lpf.b0, lpf.b1, lpf.b2)
            st[RF_BUILT], st[RF_ACTIVE] = 1.0, float(lpf.active)
            self._step(st, t_us, w[0], w[1], w[2])

    def apply(self, state: VehicleState) -> VehicleState:
        """`state` with its rate filtered (`filtered_rate`)."""
        if self.st[RF_ACTIVE] == 0.0 or self.st[RF_HAS_LAST] == 0.0:
            return state
        return state._replace(omega_flu_rad_s=filtered_rate(self.st, state.omega_flu_rad_s))

    def flown(self, est: Estimator) -> tuple[int, VehicleState] | None:
        """The estimator's output as the controller flies on it (`flown_values`), None
        before it is aligned: the pipeline's and a log replay's one path."""
        arrays = est.output_arrays()
        if arrays is None:
            return None
        t_us, p, q, v, w = self._flown(arrays[0], arrays[1], self.st)
        return t_us, VehicleState(p, q, v, w)


@njit
def filtered_rate(st: np.ndarray, w: tuple[float, float, float]
                  ) -> tuple[float, float, float]:
    """A rate less the newest sample, plus the filtered one (the newest sample less the
    bias becomes the filtered rate less the same bias); w itself while the low-pass is
    off or has no sample."""
    if st[RF_ACTIVE] == 0.0 or st[RF_HAS_LAST] == 0.0:
        return w
    return (w[0] + st[RF_OUT] - st[RF_LAST_W], w[1] + st[RF_OUT + 1] - st[RF_LAST_W + 1],
            w[2] + st[RF_OUT + 2] - st[RF_LAST_W + 2])


@njit
def flown_values(fb: np.ndarray, ib: np.ndarray, st: np.ndarray) -> tuple[
        int, tuple[float, float, float], tuple[float, float, float, float],
        tuple[float, float, float], tuple[float, float, float]]:
    """The state the controller flies on, in one compiled call: the estimator's output
    (`fcu.estimator.readout.output_values` of its arrays fb, ib), the low-pass of `st`
    applied to its rate (`ImuRateFilter.apply`), the attitude normalized (as
    `Pipeline.on_state` does): (t_us, p, q, v_flu, rate)."""
    t, p, q, v, w = output_values(fb, ib)
    return t, p, q_normalize(q), v, filtered_rate(st, w)


def _warm_up() -> None:
    st = np.zeros(RF_SIZE)
    rate_filter_step(st, 1, 0.0, 0.0, 0.0)
    fb, ib = filter_buffers(EstimatorSettings())[:2]
    flown_values(fb, ib, st)
    filtered_rate(st, (0.0, 0.0, 0.0))
