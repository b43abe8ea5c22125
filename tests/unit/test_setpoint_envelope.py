"""`manual.fit_envelope`'s limits against an independent dense check: other attitudes (seeded
random, and whole turns about random axes through them), other sampling (finite differences
along the turn), and the flight envelope's own allocation (`Envelope.omega_sq`)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from common.config import load_vehicle
from fcu import manual, offboard
from fcu.feasibility import TILT_STEP_S, envelope
from fcu.manual import StickSettings
from fcu.setpoint_envelope import THRUST_FLOOR, q_exp_n, q_mul_n
from fcu.tracker import Reference

ROOT = Path(__file__).resolve().parents[2]
TURN_SAMPLES = 1440  # per whole turn: 0.25 deg apart


def _vehicle(name: str):
    return load_vehicle(ROOT / "config" / "vehicles" / f"{name}.toml")


def dense_check(vehicle, s: StickSettings, seed: int = 7) -> tuple[float, float, float]:
    """(rotor, tilt rate, tilt step) need / limit, the worst over turns at s's rotation rate
    about 6 random axes through 6 random attitudes and level, at every acceleration corner."""
    env = envelope(vehicle)
    share = vehicle.mass_kg * vehicle.gravity_m_s2 / vehicle.n_rotors / vehicle.thrust_coeff
    rng = np.random.default_rng(seed)
    q0 = np.vstack([[1.0, 0.0, 0.0, 0.0], rng.normal(size=(6, 4))])
    q0 /= np.linalg.norm(q0, axis=1, keepdims=True)
    axes = rng.normal(size=(6, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    theta = np.linspace(0.0, 2.0 * np.pi, TURN_SAMPLES + 1)
    rate, rate_acc = math.radians(s.yaw_rate_deg_s), math.radians(s.yaw_acc_deg_s2)
    corners = [(s.acc_xy_m_s2 * math.cos(t), s.acc_xy_m_s2 * math.sin(t), az)
               for t in np.arange(8) * math.pi / 4 for az in (s.acc_up_m_s2, -s.acc_down_m_s2,
                                                              0.0)]
    worst = [0.0, 0.0, 0.0]
    zero = (0.0, 0.0, 0.0)

    def omega(q: np.ndarray, a, w=zero, wd=zero) -> np.ndarray:
        n = len(q)
        return env.omega_sq(Reference(zero, tuple(q[:, i] for i in range(4)), zero,
                                      tuple(np.full(n, float(x)) for x in a),
                                      tuple(np.full(n, float(x)) for x in w),
                                      tuple(np.full(n, float(x)) for x in wd)))

    for q_start in q0:
        for n_axis in axes:
            q = q_mul_n(q_start, q_exp_n(theta[:, None] * n_axis))
            hover = omega(q, zero)
            ok = np.sqrt(np.sqrt((hover[:, 0::2] ** 2 + hover[:, 1::2] ** 2).max(1))) \
                <= env.limit
            q, hover = q[ok], hover[ok]
            mag0, al0 = np.hypot(hover[:, 0::2], hover[:, 1::2]), \
                np.arctan2(hover[:, 0::2], hover[:, 1::2])
            w = tuple(rate * n_axis)
            wd = tuple(rate_acc * n_axis)
            for a in corners:
                om = omega(q, a, w, wd)
                worst[0] = max(worst[0], float(np.sqrt(np.sqrt(
                    (om[:, 0::2] ** 2 + om[:, 1::2] ** 2).max()))) / env.limit)
                om = omega(q, a)
                mag, al = np.hypot(om[:, 0::2], om[:, 1::2]), np.arctan2(om[:, 0::2],
                                                                           om[:, 1::2])
                step = np.abs(np.remainder(np.diff(al, axis=0) + np.pi, 2 * np.pi) - np.pi)
                dense = np.diff(theta[ok])[:, None]
                firm = np.minimum(mag[1:], mag[:-1]) >= THRUST_FLOOR * share
                per_rad = np.where(firm & (dense < 1e-2), step / dense, 0.0)
                worst[1] = max(worst[1], float(per_rad.max()) * rate / env.tilt_limit)
                back = omega(q, tuple(-x for x in a))
                for m_fr, al_fr in ((mag0, al0), (np.hypot(back[:, 0::2], back[:, 1::2]),
                                                  np.arctan2(back[:, 0::2], back[:, 1::2]))):
                    d = np.abs(np.remainder(al - al_fr + np.pi, 2 * np.pi) - np.pi)
                    weighted = d * np.minimum(1.0, np.minimum(mag, m_fr) / share)
                    worst[2] = max(worst[2], float(weighted.max())
                                   / (env.tilt_rate_max * TILT_STEP_S))
    return worst[0], worst[1], worst[2]


@pytest.mark.parametrize("name", ["hexa_tilted", "hexa_planar"])
def test_fitted_offboard_limits_pass_a_dense_check_and_the_defaults_do_not(name):
    """Given OFFBOARD's default limits (3 m/s^2, 90 deg/s about any axis), then the dense
    check finds a tilt servo outrun and a tilt step too large; fitted at a level entry, then
    rotor speed and tilt rate stay within 5 % of their limits, and the tilt step within 15 %:
    its thrust-weighted peaks are sharp, and the fit's 1024-attitude sample finds 0.80 on the
    planar preset where 65536 attitudes find 1.11 (a known gap of the fit)."""
    vehicle = _vehicle(name)
    defaults = offboard.limits(StickSettings())
    before = dense_check(vehicle, defaults)
    assert before[1] > 2.0 and before[2] > 1.5, before
    fitted = manual.fit_envelope(defaults, vehicle, (1.0, 0.0, 0.0, 0.0), any_axis=True)
    assert fitted.acc_xy_m_s2 < defaults.acc_xy_m_s2
    assert fitted.yaw_rate_deg_s < defaults.yaw_rate_deg_s
    after = dense_check(vehicle, fitted)
    assert after[0] <= 1.05 and after[1] <= 1.05 and after[2] <= 1.15, (fitted, after)


def test_posctl_keeps_its_yaw_rate_and_judges_the_tilt_steps():
    """Given POSCTL's defaults at a level entry on the tilted preset, then the yaw rate (no
    tilt moves as a level vehicle yaws) stays 90 deg/s and the accelerations are halved
    until the tilt steps fit."""
    vehicle = _vehicle("hexa_tilted")
    fitted = manual.fit_envelope(StickSettings(), vehicle, (1.0, 0.0, 0.0, 0.0))
    assert fitted.yaw_rate_deg_s == StickSettings().yaw_rate_deg_s
    assert fitted.acc_xy_m_s2 < StickSettings().acc_xy_m_s2
    assert manual.needs(vehicle, (1.0, 0.0, 0.0, 0.0), fitted).step_ratio <= 1.0
    doubled = StickSettings(acc_xy_m_s2=2 * fitted.acc_xy_m_s2,
                            acc_up_m_s2=2 * fitted.acc_up_m_s2,
                            acc_down_m_s2=2 * fitted.acc_down_m_s2,
                            yaw_acc_deg_s2=2 * fitted.yaw_acc_deg_s2)
    assert manual.needs(vehicle, (1.0, 0.0, 0.0, 0.0), doubled).step_ratio > 1.0
