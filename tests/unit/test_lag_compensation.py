"""Lag compensation of the allocation (CA_LAG_COMP): the rotor speed lead for the first-order
lag with unequal up/down constants, the tilt lead for the servo's rate limit, the lead taken
from the reference only, and CA_LAG_COMP 0 as the plain allocation bit for bit."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from common.config.scenario import load_scenario, load_vehicle
from fcu.control.allocation import (
    ActuatorFigures,
    Allocator,
    LagCompensator,
    speed_lead,
    tilt_lead,
)
from fcu.control.core import FlightCore
from fcu.control.tracker import DualQuaternionTracker
from fcu.params import BY_NAME, ParamError, ParamStore, apply_params
from fcu.pipeline import Pipeline
from fcu.reference.trajectory import make_trajectory
from fcu.stages import VehicleState
from sitl.plant import Plant

ROOT = Path(__file__).resolve().parents[2]
VEHICLE = load_vehicle(ROOT / "config" / "vehicles" / "hexa_tilted.toml")
FIG = ActuatorFigures.of(VEHICLE)
DT = 0.002  # control period (500 Hz)
H = 0.001  # the plant's step (1 kHz)


def rotor_period_means(commands: list[float], w0: float) -> list[float]:
    """A rotor under the plant's own lag law (sitl.plant.Plant._rotor_lag: tau_up while the
    command is above the speed, tau_down otherwise, exact over each 1 ms step), each command
    held for one control period; the exact mean speed over each period."""
    plant = Plant(VEHICLE, dt_us=round(H * 1e6))
    du, dd = math.exp(-H / FIG.tau_up_s), math.exp(-H / FIG.tau_down_s)
    w, means = w0, []
    for c in commands:
        total = 0.0
        for _ in range(round(DT / H)):
            tau = FIG.tau_up_s if c > w else FIG.tau_down_s
            total += c + (w - c) * tau / H * (1.0 - math.exp(-H / tau))
            w = plant._rotor_lag([w], [c], du, dd)[0]
        means.append(total / round(DT / H))
    return means


def servo_period_means(commands: list[float], a0: float) -> list[float]:
    """A tilt servo under the plant's law (a0 + clamp(c - a0, -R t, R t) over each held
    command); the exact mean tilt over each period."""
    rate, a, means = FIG.tilt_rate_max_rad_s, a0, []
    for c in commands:
        d = c - a
        t_reach = min(abs(d) / rate, DT)
        moved = math.copysign(rate * t_reach, d)
        # ramp for t_reach, then at rest for the rest of the period
        means.append(a + (0.5 * moved * t_reach + moved * (DT - t_reach)) / DT)
        a += moved
    return means


# ------------------------------------------------------------------ rotor speed


@pytest.mark.parametrize("slope", [400.0, -400.0])
def test_speed_lead_follows_a_ramp_without_steady_lag(slope):
    """Given a rotor speed ramp (up and down) and then a hold, when each period's command is
    the target plus speed_lead, then the lagged rotor's mean over each period equals the
    target an ideal rotor holds (to 0.1 % of the plain allocation's lag), during the ramp and
    after it; the plain command lags by tau w' (tau_up rising, tau_down falling)."""
    w0, n_ramp, n_hold = 900.0, 400, 200
    targets = [w0 + slope * DT * min(k, n_ramp) for k in range(n_ramp + n_hold)]
    rates = [(targets[k] - targets[k - 1]) / DT if k else 0.0 for k in range(len(targets))]
    led = rotor_period_means([t + speed_lead(r, FIG) for t, r in zip(targets, rates,
                                                                     strict=True)], w0)
    plain = rotor_period_means(targets, w0)
    tau = FIG.tau_up_s if slope > 0 else FIG.tau_down_s
    ramp = slice(n_ramp // 2, n_ramp)  # the ramp's steady part (over 16 tau)
    lag_plain = np.array(targets[ramp]) - np.array(plain[ramp])
    assert lag_plain == pytest.approx(tau * slope, rel=0.02)
    err = np.abs(np.array(targets) - np.array(led))
    assert err[ramp].max() < 1e-3 * abs(tau * slope)
    assert err[-20:].max() < 1e-6  # at rest after the ramp (16 tau_down): no offset left


def test_speed_lead_uses_the_constant_of_the_direction():
    """tau_up on a rising ramp, tau_down (here twice as long) on a falling one."""
    assert FIG.tau_down_s != FIG.tau_up_s
    assert speed_lead(100.0, FIG) == pytest.approx(100.0 * FIG.tau_up_s)
    assert speed_lead(-100.0, FIG) == pytest.approx(-100.0 * FIG.tau_down_s)
    assert speed_lead(0.0, FIG) == 0.0


# ------------------------------------------------------------------ tilt servo


@pytest.mark.parametrize("rate", [2.0, -3.0])
def test_tilt_lead_makes_the_rate_limited_servo_mean_exact(rate):
    """Given a tilt ramp slower than the servo's limit, when each command is the target plus
    tilt_lead, then the servo's mean over each period equals the target (an ideal servo's
    held command); without it the servo falls short by r|r| dt / (2 R)."""
    n = 200
    targets = [0.3 + rate * DT * k for k in range(n)]
    led = servo_period_means([t + tilt_lead(rate, DT, FIG) for t in targets], targets[0])
    plain = servo_period_means(targets, targets[0])
    short = rate * abs(rate) * DT / (2.0 * FIG.tilt_rate_max_rad_s)
    assert np.array(targets[10:]) - np.array(plain[10:]) == pytest.approx(short, rel=1e-6)
    assert np.abs(np.array(targets[10:]) - np.array(led[10:])).max() < 1e-3 * abs(short)


def test_tilt_ramp_faster_than_the_limit_is_led():
    """Given a tilt ramp faster than the servo's limit, then the command is led by R dt / 2
    in the ramp's direction and the servo, at its limit, is never behind the plain one."""
    r_max = FIG.tilt_rate_max_rad_s
    for rate in (1.5 * r_max, -3.0 * r_max):
        lead = tilt_lead(rate, DT, FIG)
        assert lead == pytest.approx(math.copysign(0.5 * r_max * DT, rate))
        targets = [rate * DT * k for k in range(50)]
        led = servo_period_means([t + lead for t in targets], 0.0)
        plain = servo_period_means(targets, 0.0)
        assert all(math.copysign(1.0, rate) * (x - y) >= -1e-12
                   for x, y in zip(led, plain, strict=True))
    # continuous at the limit, increasing with the rate below it
    assert tilt_lead(r_max * (1 - 1e-9), DT, FIG) == pytest.approx(0.5 * r_max * DT)
    assert 0.0 < tilt_lead(1.0, DT, FIG) < tilt_lead(2.0, DT, FIG)


# ------------------------------------------------------------------ in the control step


def _case1_samples(t0: float, n: int):
    traj = make_trajectory(load_scenario(ROOT / "config" / "scenarios" /
                                         "case1_figure8.toml").trajectory)
    return [traj.sample(t0 + k * DT) for k in range(n)]


def _noisy_states(refs, seed: int) -> list[VehicleState]:
    rng = np.random.default_rng(seed)
    out = []
    for r in refs:
        n = rng.standard_normal(9)
        p = tuple(x + 1e-3 * e for x, e in zip(r.p_enu_m, n[:3], strict=True))
        q = r.q_enu_flu
        out.append(VehicleState(p, q, tuple(0.02 * n[3:6]), tuple(0.01 * n[6:9])))
    return out


def test_lag_comp_off_is_the_plain_allocation_bit_for_bit():
    """CA_LAG_COMP 0: FlightCore's allocation is the plain allocation of the tracker's
    wrench, exactly, step after step (also after switching off mid-flight)."""
    refs = _case1_samples(25.0, 60)
    states = _noisy_states(refs, 1)
    gains = load_scenario(ROOT / "config" / "scenarios" / "case1_figure8.toml").gains
    core = FlightCore(VEHICLE, gains, 500, lag_compensation=False)
    tracker, alloc = DualQuaternionTracker(VEHICLE, gains), Allocator(VEHICLE)
    for k, (s, r) in enumerate(zip(states, refs, strict=True)):
        if k == 30:  # on and off again: the plain allocation all the same
            core.set_lag_compensation(True)
            core.set_lag_compensation(False)
        got = core.step(s, r)
        out = tracker.update(s, r, DT)
        assert got.tracker == out
        assert got.allocation == alloc.allocate(out.force_flu_n, out.torque_flu_nm)


def test_lead_depends_on_the_reference_only():
    """Given the same reference flown from two differently noisy state sequences, then the
    compensated commands differ from the plain ones by the lead, which is the reference's
    alone (the state's noise passes with gain 1, never amplified), less the slow mean
    correction, which moves by at most dt / T of the noise per period; the lead is not zero
    on the figure-infinity, leads each speed the way the nominal speed moves, with tau_up
    rising and tau_down falling."""
    from fcu.control.allocation import MEAN_TAU_S
    from fcu.envelope.feasibility import nominal_wrench

    refs = _case1_samples(30.0, 40)
    gains = load_scenario(ROOT / "config" / "scenarios" / "case1_figure8.toml").gains
    diffs = []
    for seed in (1, 2):
        on = FlightCore(VEHICLE, gains, 500, lag_compensation=True)
        off = FlightCore(VEHICLE, gains, 500, lag_compensation=False)
        rows = []
        for s, r in zip(_noisy_states(refs, seed), refs, strict=True):
            a, b = on.step(s, r).allocation, off.step(s, r).allocation
            rows.append(np.subtract(a.speed_rad_s, b.speed_rad_s).tolist()
                        + np.subtract(a.tilt_rad, b.tilt_rad).tolist())
        diffs.append(np.array(rows))
    # tilts: the lead only; speeds: the lead less a correction of at most ~(k dt / T) 15 rad/s
    assert np.abs(diffs[0][:, 6:] - diffs[1][:, 6:]).max() < 1e-9
    steps = np.arange(len(refs))[:, None]
    assert np.all(np.abs(diffs[0][:, :6] - diffs[1][:, :6]) <= steps * DT / MEAN_TAU_S * 30.0)
    assert np.abs(diffs[0][0]).max() == 0.0  # first period: nothing to difference yet
    comp = LagCompensator(VEHICLE)
    leads = np.array([comp.lead(*nominal_wrench(VEHICLE, r), DT)[0] for r in refs])
    nominal = np.array([comp.nominal(*nominal_wrench(VEHICLE, r))[0] for r in refs])
    rates = np.diff(nominal, axis=0) / DT
    assert np.abs(leads[1:]).min() > 0.0
    assert np.all(np.sign(leads[1:]) == np.sign(rates))
    expected = np.where(rates > 0, FIG.tau_up_s, FIG.tau_down_s) * rates
    assert leads[1:] == pytest.approx(expected, rel=1e-9, abs=1e-9)


def test_mean_correction_removes_the_rectified_thrust():
    """Given a command jittering about a constant (noise through the feedback), the lagged
    rotor's mean thrust exceeds the ideal rotor's (it rises faster than it falls); the
    compensator's correction, driven by its rotor model, brings the mean back, and the
    plant's rotor under the corrected commands agrees."""
    from fcu.control.allocation import AllocationResult, rotor_period

    rng = np.random.default_rng(3)
    n, w0 = 3000, 900.0
    u = w0 + 15.0 * rng.standard_normal(n)  # the plain allocation's speeds (one rotor)
    comp = LagCompensator(VEHICLE)
    zero = (0.0,) * 6
    sent = []
    for x in u:
        plain = AllocationResult((0.0,) * 12, (float(x),) * 6, zero, zero, False)
        sent.append(comp.apply(plain, zero, zero, DT).speed_rad_s[0])

    def thrust_excess(commands):
        w, total = w0, 0.0
        for c in commands[n // 2:]:
            w, m2 = rotor_period(w, c, DT, FIG)
            total += m2
        return total / (n - n // 2) - float(np.mean(u[n // 2:] ** 2))

    plain_excess, led_excess = thrust_excess(list(u)), thrust_excess(sent)
    assert plain_excess > 0.5 * 15.0 ** 2 * 0.1  # rectified: well above zero
    assert abs(led_excess) < 0.1 * plain_excess
    # the model is the plant's rotor: the same end speed after a period, and mean w^2 by
    # fine quadrature of the exact trajectory
    plant = Plant(VEHICLE, dt_us=round(H * 1e6))
    du, dd = math.exp(-H / FIG.tau_up_s), math.exp(-H / FIG.tau_down_s)
    for w_start, c in ((900.0, 960.0), (900.0, 850.0), (0.0, 700.0)):
        w = w_start
        for _ in range(round(DT / H)):
            w = plant._rotor_lag([w], [c], du, dd)[0]
        end, m2 = rotor_period(w_start, c, DT, FIG)
        tau = FIG.tau_up_s if c > w_start else FIG.tau_down_s
        t = np.linspace(0.0, DT, 20001)
        traj = c + (w_start - c) * np.exp(-t / tau)
        assert end == pytest.approx(w, rel=1e-12)
        assert m2 == pytest.approx(float(np.trapezoid(traj ** 2, t)) / DT, rel=1e-8)


def test_parameter_reaches_the_core():
    """CA_LAG_COMP is an enum parameter, 1 by default; apply_params puts it in force."""
    spec = BY_NAME["CA_LAG_COMP"]
    assert (spec.default, spec.lo, spec.hi, spec.unit) == (1.0, 0.0, 1.0, "enum")
    gains = load_scenario(ROOT / "config" / "scenarios" / "case1_figure8.toml").gains
    store, pipeline = ParamStore(gains), Pipeline(VEHICLE, gains, 500)
    assert not pipeline.core.lag_compensation  # FlightCore alone: the plain allocation
    apply_params(store, pipeline)
    assert pipeline.core.lag_compensation
    store.set("CA_LAG_COMP", 0.0)
    apply_params(store, pipeline)
    assert not pipeline.core.lag_compensation
    with pytest.raises(ParamError):
        store.set("CA_LAG_COMP", 0.5)
