"""The in-flight actuator monitor (fcu/safety/actuator_monitor.py, COM_ACT_RATE_T): a model of each
tilt servo driven by the commands (the plant's rate limit) and each rotor's speed clamp."""

from __future__ import annotations

import math
import random

import pytest

from common.config.scenario import load_gains, load_vehicle
from fcu.params import ParamStore, apply_params
from fcu.pipeline import Pipeline
from fcu.safety.actuator_monitor import ActuatorMonitor, LimitNotice, unclamped_speeds
from sitl.plant import ActuatorCommand, Plant

from .test_allocation import PRESETS, ROOT, vehicle_path

R = 4.0  # rad/s, the vehicles' tilt rate limit
W_MAX = 1700.0  # rad/s
HOLD = 1.0  # rad/s, the allocation's hold speed
DT = 0.002  # s, 500 Hz
T = 0.1  # s, COM_ACT_RATE_T's default
SPIN = (800.0,) * 6  # rotors well inside their range, above the hold speed
ROTORS = range(6)


def _monitor() -> ActuatorMonitor:
    return ActuatorMonitor(6, R, W_MAX, HOLD, (0.0,) * 6)


def _tilts(servo: int, value: float) -> tuple[float, ...]:
    return tuple(value if i == servo else 0.0 for i in range(6))


def _fly(mon: ActuatorMonitor, tilts: list[tuple[float, ...]], speeds=SPIN,
         limit_s: float = T) -> tuple[list[tuple[int, LimitNotice]], list[list[bool]]]:
    """Each period's commands through the monitor: the notices (with their period) and the
    servos' limited flags per period."""
    notices, flags = [], []
    for k, cmd in enumerate(tilts):
        notices += [(k, n) for n in mon.update(DT, cmd, speeds, limit_s)]
        flags.append(list(mon.tilt_limited))
    return notices, flags


def _runs(flags: list[bool]) -> list[int]:
    """Lengths (periods) of the runs of True."""
    out, n = [], 0
    for f in [*flags, False]:
        if f:
            n += 1
        elif n:
            out.append(n)
            n = 0
    return out


@pytest.mark.parametrize("servo", ROTORS)
def test_a_ramp_within_the_rate_is_never_limited(servo):
    """Given servo i commanded along a ramp at 0.95 R for 2 s, then the model follows it,
    the servo is never limited and nothing is said."""
    mon = _monitor()
    ramp = [_tilts(servo, 0.95 * R * DT * (k + 1)) for k in range(1000)]
    notices, flags = _fly(mon, ramp)
    assert notices == [] and not any(map(any, flags))
    assert mon.model_rad[servo] == pytest.approx(0.95 * R * 2.0)


@pytest.mark.parametrize("servo", ROTORS)
@pytest.mark.parametrize(("step_rad", "reported"), [(0.8, True), (0.3, False)])
def test_a_step_is_limited_for_step_over_rate_only(servo, step_rad, reported):
    """Given a step of the command of servo i, then the servo is limited for step / R
    (less the period that reaches it) once, and it is reported only when that is longer
    than COM_ACT_RATE_T (0.8 rad: 0.2 s; 0.3 rad: 0.075 s), then cleared; no other servo
    is limited."""
    mon = _monitor()
    notices, flags = _fly(mon, [_tilts(servo, step_rad)] * 200)
    runs = _runs([f[servo] for f in flags])
    # limited in every period but the one that reaches the command
    assert len(runs) == 1 and step_rad / R - DT < runs[0] * DT + 1e-12 <= step_rad / R + 2e-12
    assert not any(f[i] for f in flags for i in range(6) if i != servo)
    assert mon.model_rad[servo] == step_rad  # the servo landed on its command
    kinds = [(n.kind, n.actuator) for _, n in notices]
    assert kinds == ([("tilt", servo), ("clear", -1)] if reported else [])
    if reported:
        assert notices[0][0] == round(T / DT)  # the first period limited longer than T
        assert notices[1][0] == runs[0]  # the first period not limited


@pytest.mark.parametrize("servo", ROTORS)
def test_a_sustained_fast_ramp_is_reported_once_with_its_rate(servo):
    """Given servo i commanded along a ramp at 3.3 R for 1 s, then held, then exactly one
    WARNING names servo i (1-based) with the ramp's rate and the limit, and "actuator limits
    cleared" follows once the model has caught up with the command."""
    mon = _monitor()
    rate = 3.3 * R
    ramp = [_tilts(servo, rate * DT * (k + 1)) for k in range(500)]
    notices, flags = _fly(mon, ramp + [ramp[-1]] * 1500)
    assert [(n.kind, n.actuator) for _, n in notices] == [("tilt", servo), ("clear", -1)]
    warning = notices[0][1]
    assert warning.demanded == pytest.approx(rate, rel=1e-9) and warning.limit == R
    assert warning.text(T) == f"tilt servo {servo + 1} rate-limited 0.1 s: 13.2 > 4 rad/s"
    # the model lags at R for as long as it takes to reach 13.2 rad at 4 rad/s: 3.3 s
    assert abs(notices[1][0] * DT - rate * 1.0 / R) <= DT
    assert _runs([f[servo] for f in flags]) == [notices[1][0]]


@pytest.mark.parametrize("rotor", ROTORS)
def test_a_rotor_clamped_longer_than_the_time_is_named(rotor):
    """Given rotor i's unclamped speed over w_max for 0.3 s (peak 1900 rad/s), then one
    WARNING names rotor i (1-based) with the highest speed so far, then "cleared"; a clamp
    of 0.06 s and a speed at w_max exactly are not reported."""
    mon = _monitor()
    hold = (0.0,) * 6
    def speeds(w: float) -> tuple[float, ...]:
        return tuple(w if i == rotor else 800.0 for i in range(6))
    profile = ([speeds(1800.0)] * 100 + [speeds(1900.0)] * 50 + [speeds(1000.0)] * 10
               + [speeds(1800.0)] * 30 + [speeds(W_MAX)] * 100)
    notices = []
    for k, sp in enumerate(profile):
        notices += [(k, n) for n in mon.update(DT, hold, sp, T)]
        assert mon.rotor_limited == [i == rotor and sp[i] > W_MAX for i in range(6)]
    assert [(n.kind, n.actuator) for _, n in notices] == [("rotor", rotor), ("clear", -1)]
    assert [k for k, _ in notices] == [round(T / DT), 150]
    assert notices[0][1].text(T) == f"rotor {rotor + 1} at speed limit 0.1 s: 1800 > 1700 rad/s"


@pytest.mark.parametrize("limit_s", [0.05, 0.1, 0.3])
def test_the_parameter_sets_the_time(limit_s):
    """Given servo 3 commanded a step of 0.8 rad (0.2 s at R), then with COM_ACT_RATE_T =
    limit_s it is reported in the first period limited longer than limit_s, or never when
    the step takes less."""
    mon = _monitor()
    notices, _ = _fly(mon, [_tilts(2, 0.8)] * 200, limit_s=limit_s)
    tilt = [k for k, n in notices if n.kind == "tilt"]
    assert tilt == ([round(limit_s / DT)] if limit_s < 0.2 else [])


def test_com_act_rate_t_reaches_the_pipeline():
    """COM_ACT_RATE_T (default 0.1 s) is the pipeline's time; a set puts it in force."""
    gains = load_gains(ROOT / "config/gains/pid_eq30.toml")
    pipeline = Pipeline(load_vehicle(vehicle_path("hexa_tilted")), gains, 500)
    store = ParamStore(gains)
    apply_params(store, pipeline)
    assert pipeline.settings.actuator_limit_s == pytest.approx(0.1)
    store.set("COM_ACT_RATE_T", 0.5)
    apply_params(store, pipeline)
    assert pipeline.settings.actuator_limit_s == pytest.approx(0.5)


def test_a_servo_of_a_rotor_below_the_hold_speed_is_not_judged():
    """Given a step of servo 2's command while rotor 2 turns below the hold speed (the
    allocation holds its tilt, its direction undefined), then it is not limited, but its
    model still moves at R."""
    mon = _monitor()
    slow = (800.0, 0.5, 800.0, 800.0, 800.0, 800.0)
    notices, flags = _fly(mon, [_tilts(1, 0.8)] * 100, speeds=slow)
    assert notices == [] and not any(map(any, flags))
    assert mon.model_rad[1] == pytest.approx(100 * R * DT)


def test_tilts_are_not_wrapped():
    """Given the model at pi - 0.01 and a command of -pi + 0.01 (the same direction modulo
    2 pi), then the servo must turn 2 pi - 0.02 the other way, as the plant's servo does."""
    mon = ActuatorMonitor(6, R, W_MAX, HOLD, (math.pi - 0.01,) * 6)
    mon.update(DT, (-math.pi + 0.01,) * 6, SPIN, T)
    assert mon.tilt_limited == [True] * 6
    assert mon.model_rad == [pytest.approx(math.pi - 0.01 - R * DT)] * 6


def test_reset_settles_the_model_and_ends_episodes_silently():
    """Given a reported episode, when reset (disarm, arming) at the commanded tilts, then
    the model is there, no notice comes, and the same command is then not limited."""
    mon = _monitor()
    notices, _ = _fly(mon, [_tilts(0, 1.0)] * 60)
    assert [n.kind for _, n in notices] == ["tilt"]
    mon.reset(_tilts(0, 1.0))
    assert mon.model_rad == list(_tilts(0, 1.0)) and not any(mon.reported)
    assert mon.update(DT, _tilts(0, 1.0), SPIN, T) == [] and not any(mon.tilt_limited)


@pytest.mark.parametrize("vehicle", PRESETS)
def test_the_model_is_the_plants_servo(vehicle):
    """Given random tilt commands (steps, ramps, holds, across +-pi), held one control
    period each, then the model's tilts are the plant's servos' (sitl/plant.py) after each
    period, to rounding."""
    v = load_vehicle(vehicle_path(vehicle))
    plant = Plant(v, dt_us=1000)
    mon = ActuatorMonitor(6, v.tilt_rate_max_rad_s, v.rotor_speed_max_rad_s, HOLD)
    rng = random.Random(7)
    tilt, speed = [0.0] * 6, [0.0] * 6
    cmd = [0.0] * 6
    for _ in range(2000):
        cmd = [c + rng.choice((0.0, rng.gauss(0.0, 0.01), rng.uniform(-2.0, 2.0)))
               for c in cmd]
        mon.update(DT, cmd, SPIN, T)
        speed, tilt = plant.actuators_at(tuple(speed), tuple(tilt),
                                         ActuatorCommand(SPIN, tuple(cmd)), DT)
        assert mon.model_rad == pytest.approx(tilt, abs=1e-12)


def test_unclamped_speeds_are_the_allocations():
    """(lat^2 + ver^2)^(1/4) per rotor from Omega's pairs."""
    assert unclamped_speeds((3.0e6, 4.0e6, 0.0, 1.0e4)) == pytest.approx((math.sqrt(5e6), 100.0))


def test_texts_fit_statustext():
    """Every notice fits a STATUSTEXT (50 characters) over the parameter's range."""
    for limit_s in (0.002, 0.1, 0.25, 60.0):
        for n in (LimitNotice("tilt", 5, 1234.5, 4.0), LimitNotice("rotor", 5, 9999.0, 1700.0),
                  LimitNotice("clear")):
            assert len(n.text(limit_s)) <= 50
    assert LimitNotice("clear").text(T) == "actuator limits cleared"


def test_the_allocations_omega_gives_what_its_unclamped_speeds_give():
    """Given random commands with rotors pushed past w_max now and then, fed once as the
    allocation's Omega pairs (the control step's path) and once as `unclamped_speeds` of
    them, then both monitors say the same notices with the same figures, period by period,
    and hold the same state."""
    rng = random.Random(11)
    by_omega, by_speed = _monitor(), _monitor()
    said = []
    w = [800.0] * 6
    for k in range(3000):
        if k % 80 == 0:  # speeds held 80 periods (0.16 s), some past w_max
            w = [rng.choice((800.0, 1650.0, 1750.0, 1900.0)) for _ in ROTORS]
        a = [rng.uniform(-0.3, 0.3) for _ in ROTORS]
        omega = tuple(x for wi, ai in zip(w, a, strict=True)
                      for x in (wi * wi * math.sin(ai), wi * wi * math.cos(ai)))
        tilts = tuple(0.5 * math.sin(0.001 * k + i) for i in ROTORS)  # within the rate
        got = by_omega.update_from_allocation(DT, tilts, omega, T)
        assert got == by_speed.update(DT, tilts, unclamped_speeds(omega), T), k
        said += got
    assert by_omega.st.tobytes() == by_speed.st.tobytes()
    assert {"rotor", "clear"} <= {n.kind for n in said}
