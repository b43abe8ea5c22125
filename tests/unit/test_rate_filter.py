"""The gyro's low-pass (fcu/control/rate_filter.py, PX4's IMU_GYRO_CUTOFF): a second-order
Butterworth filter per axis."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fcu.control.rate_filter import GyroLowPass


def _gain(f_hz: float, cutoff_hz: float = 40.0, rate_hz: float = 1000.0) -> float:
    lpf = GyroLowPass(rate_hz, cutoff_hz)
    n = 4000
    t = np.arange(n) / rate_hz
    out = np.array([lpf.update((math.sin(2 * math.pi * f_hz * ti), 0.0, 1.0))[0]
                    for ti in t])
    return float(np.std(out[n // 2:]) / np.std(np.sin(2 * math.pi * f_hz * t[n // 2:])))


def test_butterworth_response():
    """Unity at low frequency, -3 dB at the cut-off, -40 dB/decade above it."""
    assert _gain(1.0) == pytest.approx(1.0, abs=0.01)
    assert _gain(40.0) == pytest.approx(1 / math.sqrt(2), abs=0.02)
    assert _gain(200.0) < 0.05


def test_constant_passes_exactly_and_starts_at_rest():
    lpf = GyroLowPass(1000.0, 40.0)
    assert lpf.update((0.3, -0.2, 0.1)) == (0.3, -0.2, 0.1)  # starts on the first sample
    for _ in range(50):
        y = lpf.update((0.3, -0.2, 0.1))
    assert y == pytest.approx((0.3, -0.2, 0.1), abs=1e-12)


def test_non_finite_sample_is_held_out_and_zero_cutoff_passes_through():
    lpf = GyroLowPass(1000.0, 40.0)
    lpf.update((1.0, 1.0, 1.0))
    held = lpf.update((math.nan, 0.0, 0.0))
    assert held == (1.0, 1.0, 1.0) and all(math.isfinite(c) for c in lpf.update((1.0,) * 3))
    off = GyroLowPass(1000.0, 0.0)
    assert not off.active and off.update((5.0, 6.0, 7.0)) == (5.0, 6.0, 7.0)
    with pytest.raises(ValueError):
        GyroLowPass(0.0, 40.0)
    with pytest.raises(ValueError):
        GyroLowPass(1000.0, -1.0)


def _reference_update(lpf: GyroLowPass, d1: list[float], d2: list[float],
                      x: tuple[float, float, float]) -> tuple[float, ...]:
    """PX4's LowPassFilter2p::apply per axis, written as a loop (the filter's arithmetic in
    its order)."""
    y = []
    for i in range(3):
        d0 = x[i] - d1[i] * lpf.a1 - d2[i] * lpf.a2
        y.append(d0 * lpf.b0 + d1[i] * lpf.b1 + d2[i] * lpf.b2)
        d2[i], d1[i] = d1[i], d0
    return tuple(y)


def test_each_output_is_the_per_axis_recursion_to_the_bit():
    """The unrolled update against the recursion axis by axis, over noisy samples with
    non-finite ones held out."""
    rng = np.random.default_rng(2)
    lpf = GyroLowPass(1000.0, 40.0)
    x0 = (0.3, -0.2, 0.1)
    lpf.update(x0)
    d1 = [c / (1.0 + lpf.a1 + lpf.a2) for c in x0]
    d2 = list(d1)
    for k in range(2000):
        v = rng.normal(0.0, 2.0, 3)
        x = (float(v[0]), float(v[1]), math.nan if k % 97 == 5 else float(v[2]))
        got = lpf.update(x)
        if not math.isfinite(x[2]):
            continue
        want = _reference_update(lpf, d1, d2, x)
        assert np.array(got).tobytes() == np.array(want).tobytes()


def test_the_pipelines_filter_is_the_low_pass_at_the_imus_rate_to_the_bit():
    """Given gyro samples at 1 kHz with non-finite ones among them, then `ImuRateFilter`
    (one compiled call a sample) gives through `apply` what a GyroLowPass built at the rate
    of the first two finite samples gives, sample by sample, to the bit; before its second
    finite sample, and with the cut-off at 0, the state passes unchanged."""
    from fcu.control.rate_filter import ImuRateFilter
    from fcu.stages import VehicleState

    rng = np.random.default_rng(5)
    rf, off = ImuRateFilter(40.0), ImuRateFilter(0.0)
    ref: GyroLowPass | None = None
    last: tuple[int, tuple[float, float, float]] | None = None
    for k in range(1500):
        v = rng.normal(0.0, 1.0, 3)
        w = (float(v[0]), math.inf if k % 211 == 7 else float(v[1]), float(v[2]))
        t_us = 3_000 + 1_000 * k
        rf.update(t_us, w)
        off.update(t_us, w)
        if all(math.isfinite(c) for c in w):
            if ref is None and last is not None:
                ref = GyroLowPass(1e6 / (t_us - last[0]), 40.0)
            if ref is not None:
                ref.update(w)
            last = (t_us, w)
        s = VehicleState((0.0, 0.0, 1.0), (1.0, 0.0, 0.0, 0.0), (0.0,) * 3, (0.1, -0.2, 0.3))
        assert off.apply(s) is s
        if ref is None or last is None:
            assert rf.apply(s) is s
            continue
        f, r = ref.output, last[1]
        want = (0.1 + f[0] - r[0], -0.2 + f[1] - r[1], 0.3 + f[2] - r[2])
        got = rf.apply(s).omega_flu_rad_s
        assert np.array(got).tobytes() == np.array(want).tobytes(), k
