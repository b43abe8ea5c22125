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
