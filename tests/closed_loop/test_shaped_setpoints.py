"""OFFBOARD steps and HOLD entries are shaped to what every actuator can follow, on both
vehicle files (fcu/reference/approach.py): 170 deg attitude steps about several axes and a HOLD at
10 m/s are flown by the FCU's pipeline over the plant with no tilt servo rate-limited for
COM_ACT_RATE_T (0.1 s) and within 5 cm and 3 deg of the shaped reference; a 170 deg roll,
which no duration makes flyable (two tilts flip), is refused in attitude and held. An
acceleration shaper without a jerk limit rate-limited tilt servos for 0.9 s and more on the
roll, and lagged 7.5 cm (tilted) and 25 cm (planar) on the HOLD."""

from __future__ import annotations

import math
import random

import pytest

from common.frames import enu_to_ned, q_enu_flu_to_ned_frd
from common.quaternion import q_angle, q_conj, q_exp, q_mul
from common.wire.modes import Mode
from fcu.edge.setpoint_wire import attitude_target, position_target, sticks_from_manual_control

from ..pipeline_flight import (
    ATTITUDE_ONLY,
    LIMIT_S,
    POSITION_ONLY,
    VEHICLES,
    VELOCITY_ONLY,
    Flight,
    random_step,
)


def _step_attitude(f: Flight, axis) -> tuple:
    c = f.pipe.commander
    q_t = q_exp(tuple(math.radians(170.0) * a for a in axis))
    assert c.offboard_position(0.0, position_target(1, POSITION_ONLY, enu_to_ned((0.0, 0.0, 5.0)),
                               (0.0,) * 3, (0.0,) * 3, 0.0))[0]
    assert c.offboard_attitude(0.0, attitude_target(ATTITUDE_ONLY, q_enu_flu_to_ned_frd(q_t),
                                                    (0.0,) * 3))[0]
    assert c.set_mode(Mode.OFFBOARD, 0.0)[0] == 0
    f.step()
    assert c.modes.shaper.sp is not None
    return q_t, c.modes.shaper.sp


@pytest.mark.parametrize("vehicle", VEHICLES)
@pytest.mark.parametrize("axis", [(0.0, 1.0, 0.0), (0.7071, 0.7071, 0.0),
                                  (0.48, -0.6, 0.64), (0.7071, 0.0, 0.7071)])
def test_a_170_degree_rotation_step_in_offboard_fits_every_actuator(vehicle, axis):
    """Given a hover at 5 m, when OFFBOARD streams the same position turned 170 deg about a
    body axis (pitch, and three tilted axes), then the approach keeps every tilt servo
    within its rate (no limited period as long as COM_ACT_RATE_T, no report), the vehicle
    stays within 5 cm and 3 deg of the reference, and it ends on the pose (1 cm, 0.5 deg)
    still in OFFBOARD."""
    f = Flight(vehicle, (0.0, 0.0, 5.0))
    q_t, sp = _step_attitude(f, axis)
    plan = sp.plan
    assert plan is not None and plan.fits and not sp.refused, plan
    for _ in range(round((plan.duration_s + 1.5) * 500)):
        f.step()
    c = f.pipe.commander
    assert f.pipe.armed and c.mode == Mode.OFFBOARD and f.pipe.saturated_steps == 0
    assert f.limited_s < LIMIT_S and not f.reports(), (f.limited_s, f.reports())
    assert f.track_m < 0.05 and f.track_rad < math.radians(3.0), (f.track_m, f.track_rad)
    assert math.dist(f.state.p_enu_m, (0.0, 0.0, 5.0)) < 0.01
    assert q_angle(q_mul(q_conj(q_t), f.state.q_enu_flu)) < math.radians(0.5)


@pytest.mark.parametrize("vehicle", VEHICLES)
def test_a_170_degree_roll_that_would_flip_two_tilts_is_refused_and_held(vehicle):
    """Given a hover at 5 m, when OFFBOARD streams a 170 deg roll (about the body's forward
    axis rotors 2 and 5's thrust passes through zero: their tilts would flip half a turn,
    which flown rate-limited them for 0.9 s or more), then the attitude is not flown: the
    FCU says why in a warning, holds its attitude and position within 5 cm and 3 deg, with
    no tilt servo rate-limited."""
    f = Flight(vehicle, (0.0, 0.0, 5.0))
    _, sp = _step_attitude(f, (1.0, 0.0, 0.0))
    assert "tilt servo" in sp.refused and "flip" in sp.refused
    for _ in range(3 * 500):
        f.step()
    c = f.pipe.commander
    said = [e.text for e in c.events if e.text == sp.refused]
    assert len(said) == 1  # once, not once per sample
    assert f.pipe.armed and c.mode == Mode.OFFBOARD and f.pipe.saturated_steps == 0
    assert f.limited_s < LIMIT_S and not f.reports(), (f.limited_s, f.reports())
    assert f.track_m < 0.05 and f.track_rad < math.radians(3.0)
    assert math.dist(f.state.p_enu_m, (0.0, 0.0, 5.0)) < 0.01
    assert q_angle(f.state.q_enu_flu) < math.radians(0.5)


@pytest.mark.parametrize("vehicle", VEHICLES)
def test_hold_at_ten_metres_per_second_fits_every_actuator(vehicle):
    """Given the vehicle flying east at 10 m/s (OFFBOARD velocity set-points at 20 Hz),
    when HOLD comes, then the braking keeps every tilt servo within its rate (as does the
    speed-up), the vehicle stays within 5 cm and 3 deg of the reference, and it comes to
    rest at the hold pose, half the braking time at 10 m/s ahead (1 cm)."""
    f = Flight(vehicle, (0.0, 0.0, 5.0))
    c = f.pipe.commander

    def stream(k: int) -> None:
        if k % 25 == 0:
            assert c.offboard_position(k * 0.002, position_target(1, VELOCITY_ONLY, (0.0,) * 3,
                                       enu_to_ned((10.0, 0.0, 0.0)), (0.0,) * 3, 0.0))[0]

    stream(0)  # with the attitude held level (OFFBOARD needs a position or an attitude)
    assert c.offboard_attitude(0.0, attitude_target(
        ATTITUDE_ONLY, q_enu_flu_to_ned_frd((1.0, 0.0, 0.0, 0.0)), (0.0,) * 3))[0]
    assert c.set_mode(Mode.OFFBOARD, 0.0)[0] == 0
    k = 0
    while k < 10 * 500:
        stream(k)
        f.step()
        k += 1
        if abs(c.last_ref.v_enu_m_s[0] - 10.0) < 1e-9 and k > 500:
            break
    for _ in range(250):  # 0.5 s at 10 m/s
        stream(k)
        f.step()
        k += 1
    assert math.hypot(*f.state.v_enu_m_s[:2]) > 9.9
    at_hold = c.last_ref.p_enu_m
    assert c.set_mode(Mode.HOLD, k * 0.002)[0] == 0
    f.step()
    assert c.modes.brake.sp is not None and c.modes.brake.sp.plan is not None
    plan = c.modes.brake.sp.plan
    assert plan.fits and plan.duration_s >= 10.0 * 1.5 / 3.0 - 1e-9  # at MPC_ACC_HOR
    hold = c.modes.brake.hold
    assert hold.p_enu_m[0] - at_hold[0] == pytest.approx(10.0 * plan.duration_s / 2, abs=0.03)
    for _ in range(round((plan.duration_s + 1.0) * 500)):
        f.step()
    assert f.pipe.armed and c.mode == Mode.HOLD and f.pipe.saturated_steps == 0
    assert f.limited_s < LIMIT_S and not f.reports(), (f.limited_s, f.reports())
    assert f.track_m < 0.05 and f.track_rad < math.radians(3.0), (f.track_m, f.track_rad)
    assert math.dist(f.state.p_enu_m, hold.p_enu_m) < 0.01


@pytest.mark.parametrize("vehicle", VEHICLES)
def test_posctl_sticks_fit_every_actuator(vehicle):
    """Given a hover at 5 m in POSCTL, when the pilot pushes full forward and right with
    full yaw and throttle up for 2 s, then pulls back fully for 1 s, then centres, then the
    jerk-limited set-point keeps every tilt servo within its rate (no report) and the
    vehicle within 5 cm and 3 deg of it, and it comes to rest and holds (the set-point
    still, the vehicle within 1 cm of it)."""
    f = Flight(vehicle, (0.0, 0.0, 5.0))
    c = f.pipe.commander
    c.manual_input(0.0, sticks_from_manual_control(0, 0, 500, 0))
    assert c.set_mode(Mode.POSCTL, 0.0)[0] == 0
    for k in range(8 * 500):
        t = k * 0.002
        x, y, z, r = (1000, 1000, 1000, 1000) if t < 2.0 else \
            (-1000, 0, 500, 0) if t < 3.0 else (0, 0, 500, 0)
        c.manual_input(t, sticks_from_manual_control(x, y, z, r))
        f.step()
    assert f.pipe.armed and c.mode == Mode.POSCTL and f.pipe.saturated_steps == 0
    assert f.limited_s < LIMIT_S and not f.reports(), (f.limited_s, f.reports())
    assert f.track_m < 0.05 and f.track_rad < math.radians(3.0), (f.track_m, f.track_rad)
    ref = c.last_ref
    assert max(map(abs, (*ref.v_enu_m_s, *ref.a_enu_m_s2, *ref.omega_flu_rad_s))) == 0.0
    assert math.dist(f.state.p_enu_m, ref.p_enu_m) < 0.01
    assert math.dist(ref.p_enu_m, (0.0, 0.0, 5.0)) > 3.0  # it did fly


@pytest.mark.parametrize("vehicle", VEHICLES)
def test_random_offboard_steps_are_flown_in_the_envelope_or_refused_in_attitude(vehicle):
    """Given 12 random OFFBOARD steps per vehicle file (seeded), then each is either flown
    (no tilt servo rate-limited for COM_ACT_RATE_T, within 5 cm and 3 deg of the reference,
    ending on the pose) or, where a tilt would flip, refused in attitude with the warning and
    flown in position with the attitude held, under the same bounds."""
    rng = random.Random(f"offboard-steps-{vehicle}")
    for case in range(12):
        p_t, q_t = random_step(rng)
        f = Flight(vehicle, (0.0, 0.0, 15.0))
        c = f.pipe.commander
        assert c.offboard_position(0.0, position_target(1, POSITION_ONLY, enu_to_ned(p_t),
                                                        (0.0,) * 3, (0.0,) * 3, 0.0))[0]
        assert c.offboard_attitude(0.0, attitude_target(ATTITUDE_ONLY, q_enu_flu_to_ned_frd(q_t),
                                   (0.0,) * 3))[0]
        assert c.set_mode(Mode.OFFBOARD, 0.0)[0] == 0
        f.step()
        sp = c.modes.shaper.sp
        assert sp is not None and sp.plan is not None
        for _ in range(round((sp.plan.duration_s + 1.0) * 500)):
            f.step()
        what = (case, p_t, q_t, sp.refused, f.limited_s, f.reports(), f.track_m, f.track_rad)
        assert f.pipe.armed and f.pipe.saturated_steps == 0, what
        assert f.limited_s < LIMIT_S and not f.reports(), what
        assert f.track_m < 0.05 and f.track_rad < math.radians(3.0), what
        assert math.dist(f.state.p_enu_m, p_t) < 0.02, what
        if sp.refused:
            assert sp.refused in [e.text for e in c.events], what
            assert q_angle(f.state.q_enu_flu) < math.radians(0.5), what
        else:
            assert q_angle(q_mul(q_conj(q_t), f.state.q_enu_flu)) < math.radians(0.5), what


@pytest.mark.parametrize("vehicle", VEHICLES)
def test_random_stick_sequences_fit_every_actuator(vehicle):
    """Given 6 random stick sequences per vehicle file (seeded: every axis jumping between
    random deflections every 0.2 to 1.5 s for 6 s, entered level or at a random roll and
    pitch up to 30 deg), then POSCTL keeps every tilt servo within its rate (no report) and
    the vehicle within 5 cm and 3 deg of the set-point."""
    rng = random.Random(f"sticks-{vehicle}")
    for case in range(6):
        f = Flight(vehicle, (0.0, 0.0, 15.0))
        c = f.pipe.commander
        if case % 2:  # entered at a tilted attitude the vehicle holds
            q0 = q_exp((math.radians(rng.uniform(-30, 30)), math.radians(rng.uniform(-30, 30)),
                        0.0))
            assert c.offboard_position(0.0, position_target(
                1, POSITION_ONLY, enu_to_ned((0.0, 0.0, 15.0)), (0.0,) * 3, (0.0,) * 3, 0.0))[0]
            assert c.offboard_attitude(0.0, attitude_target(ATTITUDE_ONLY, q_enu_flu_to_ned_frd(q0),
                                       (0.0,) * 3))[0]
            assert c.set_mode(Mode.OFFBOARD, 0.0)[0] == 0
            for _ in range(round((c.modes.shaper.sp.plan.duration_s + 0.5) * 500)
                           if c.modes.shaper.sp and c.modes.shaper.sp.plan else 500):
                f.step()
        c.manual_input(0.0, sticks_from_manual_control(0, 0, 500, 0))
        assert c.set_mode(Mode.POSCTL, 0.0)[0] == 0
        t_next, sticks = 0.0, (0, 0, 500, 0)
        for k in range(6 * 500):
            t = k * 0.002
            if t >= t_next:
                sticks = (rng.randint(-1000, 1000), rng.randint(-1000, 1000),
                          rng.randint(0, 1000), rng.randint(-1000, 1000))
                t_next = t + rng.uniform(0.2, 1.5)
            c.manual_input(t, sticks_from_manual_control(*sticks))
            f.step()
        what = (case, f.limited_s, f.reports(), f.track_m, f.track_rad, c.modes.posctl.limits)
        assert f.pipe.armed and c.mode == Mode.POSCTL and f.pipe.saturated_steps == 0, what
        assert f.limited_s < LIMIT_S and not f.reports(), what
        assert f.track_m < 0.05 and f.track_rad < math.radians(3.0), what
