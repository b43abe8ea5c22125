"""The gyro's low-pass filter before the controller (PX4's IMU_GYRO_CUTOFF).

A second-order Butterworth filter per axis (PX4's LowPassFilter2p: the bilinear transform
with the cut-off pre-warped), run on every IMU sample; the controller's damping terms take
the filtered, bias-corrected rate. Pure: the sample rate and the cut-off are given.
"""

from __future__ import annotations

import math

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


class ImuRateFilter:
    """IMU_GYRO_CUTOFF on the estimator's rate: every finite gyro sample goes through a
    GyroLowPass built at the IMU's own rate (from the first two samples); `apply` gives a
    state whose rate is the newest sample less the bias (the estimator's output) the
    filtered rate less the same bias. The pipeline and a log replay share it."""

    def __init__(self, cutoff_hz: float) -> None:
        self.cutoff_hz = cutoff_hz
        self.lpf: GyroLowPass | None = None
        self.last: tuple[int, Vec3] | None = None

    def update(self, t_us: int, w: Vec3) -> None:
        isfinite = math.isfinite
        if not (isfinite(w[0]) and isfinite(w[1]) and isfinite(w[2])):
            return
        last = self.last
        self.last = (t_us, w)
        if self.lpf is None:
            if last is None or not self.cutoff_hz or t_us <= last[0]:
                return
            self.lpf = GyroLowPass(1e6 / (t_us - last[0]), self.cutoff_hz)
        self.lpf.update(w)

    def apply(self, state: VehicleState) -> VehicleState:
        lpf, last = self.lpf, self.last
        if lpf is None or not lpf.active or last is None:
            return state
        o, f, r = state.omega_flu_rad_s, lpf.output, last[1]
        return VehicleState(state.p_enu_m, state.q_enu_flu, state.v_flu_m_s,
                            (o[0] + f[0] - r[0], o[1] + f[1] - r[1], o[2] + f[2] - r[2]))
