"""The approach planner (fcu/reference/approach.py): its blend is smooth to the acceleration, a long
step cruises at the speed limit, the duration found is the shortest that fits every
actuator, a rotation that flips a tilt is found, and a new sample mid-approach keeps the
reference continuous in acceleration too."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest

from common.config.scenario import load_vehicle
from common.quaternion import q_exp
from fcu.envelope.feasibility import envelope
from fcu.modes import offboard
from fcu.modes.manual import StickSettings
from fcu.modes.offboard import Target
from fcu.reference import approach
from fcu.reference.approach import Setpoint
from fcu.reference.approach_kernels import blend, offset_kernel
from fcu.stages import Reference, pose_ref

ROOT = Path(__file__).resolve().parents[2]
LIM = offboard.limits(StickSettings())
Z = (0.0, 0.0, 0.0)
Q0 = (1.0, 0.0, 0.0, 0.0)


@pytest.mark.parametrize("r", [0.0, 0.05, 0.2, 0.4, 0.5])
def test_the_blend_goes_from_0_to_1_with_continuous_rate_and_acceleration(r):
    """B(0) = 0, B(1) = 1, B' and B'' zero at both ends; B' and B'' are B's derivatives (by
    finite differences) and continuous (no jump between samples 1e-6 apart, at the ramps'
    ends included); the top rate is 1 / (1 - r) (1.875 for the minimum-jerk r = 0)."""
    assert blend(0.0, r) == (0.0, 0.0, 0.0) and blend(1.0, r) == (1.0, 0.0, 0.0)
    h = 1e-6
    s = np.concatenate([np.linspace(h, 1.0 - h, 2001), [r, 1.0 - r, r + h, 1.0 - r - h]])
    for x in s:
        if not 2 * h <= x <= 1 - 2 * h:
            continue
        _, db, ddb = blend(x, r)
        lo, hi = blend(x - h, r), blend(x + h, r)
        assert (hi[0] - lo[0]) / (2 * h) == pytest.approx(db, abs=1e-5)
        assert (hi[1] - lo[1]) / (2 * h) == pytest.approx(ddb, abs=1e-3 + 1e-3 * abs(ddb))
        assert abs(hi[2] - lo[2]) < 1e-3 * max(1.0, 1.0 / max(r, 1e-9))
    top = max(blend(x, r)[1] for x in np.linspace(0.0, 1.0, 4001))
    assert top == pytest.approx(1.875 if r == 0.0 else 1.0 / (1.0 - r), rel=1e-4)


def test_a_long_step_cruises_at_the_speed_limit():
    """Given a 100 m step (no vehicle), then the approach cruises: it reaches MPC_VEL_MANUAL
    (5 m/s), keeps MPC_ACC_HOR, and takes about 100 / 5 + 1.875 x 5 / 3 = 23.1 s, not the
    37.5 s of one minimum-jerk blend."""
    sp = Setpoint((100.0, 0.0, 5.0), Z, Z, Q0, Z)
    x = offboard._offset(pose_ref((0.0, 0.0, 5.0), Q0), sp)
    plan = approach.plan(None, LIM, sp, x)
    assert plan is not None and plan.fits
    assert plan.duration_s == pytest.approx(100 / 5 + 1.875 * 5 / 3, rel=0.03)
    taus = np.linspace(0.0, plan.duration_s, 5001)
    rates = [offset_kernel(plan.coeffs, plan.duration_s, t) for t in taus]
    speed = max(math.hypot(*o[1][:2]) for o in rates)
    acc = max(math.hypot(*o[2][:2]) for o in rates)
    assert 4.9 < speed <= 5.0 + 1e-9 and 2.8 < acc <= 3.0 + 1e-9


@pytest.mark.parametrize(("vehicle", "axis"), [("hexa_tilted", (0.7071, 0.7071, 0.0)),
                                              ("hexa_tilted", (0.0, 1.0, 0.0)),
                                              ("hexa_planar", (0.7071, 0.0, 0.7071))])
def test_the_duration_found_is_the_shortest_that_fits_every_actuator(vehicle, axis):
    """Given a 150 deg turn about an axis where the tilt servos bind, then the plan fits the
    envelope, and the same approach 1.5 REFINE_TOL shorter does not (it was stretched by an
    actuator, not by the speed limits alone, which allow a shorter one)."""
    env = envelope(load_vehicle(ROOT / "config" / "vehicles" / f"{vehicle}.toml"))
    q = q_exp(tuple(math.radians(150.0) * a for a in axis))
    sp = Setpoint((0.0, 0.0, 5.0), Z, Z, q, Z)
    x = offboard._offset(pose_ref((0.0, 0.0, 5.0), Q0), sp)
    plan = approach.plan(env, LIM, sp, x)
    free = approach.plan(None, LIM, sp, x)
    assert plan is not None and free is not None and plan.fits
    assert plan.duration_s > 1.2 * free.duration_s  # the envelope binds
    assert plan.excess is not None and plan.excess.kind == "tilt servo"
    r = float(plan.coeffs[0, 6])
    assert approach.check(env, LIM, sp, x, plan.duration_s, r)[0] <= 1.0
    shorter = plan.duration_s * (1.0 - 1.5 * approach.REFINE_TOL)
    assert approach.check(env, LIM, sp, x, shorter, r)[0] > 1.0


@pytest.mark.parametrize("vehicle", ["hexa_tilted", "hexa_planar"])
def test_a_roll_that_passes_a_rotor_through_zero_thrust_is_a_flip(vehicle):
    """A 120 deg roll about the body's forward axis takes rotors 2 and 5 through zero thrust
    (their tilts would flip half a turn): `flip` names one of them; a 120 deg pitch has no
    flip."""
    env = envelope(load_vehicle(ROOT / "config" / "vehicles" / f"{vehicle}.toml"))
    start = pose_ref((0.0, 0.0, 5.0), Q0)
    for axis, flips in (((1.0, 0.0, 0.0), True), ((0.0, 1.0, 0.0), False)):
        sp = Setpoint((0.0, 0.0, 5.0), Z, Z, q_exp(tuple(math.radians(120) * a for a in axis)),
                      Z)
        found = approach.flip(env, sp, offboard._offset(start, sp), 3.0)
        assert (found is not None) == flips, axis
        if found is not None:
            assert found.kind == approach.FLIP and found.number in (2, 5)


def test_a_new_sample_mid_approach_keeps_the_acceleration_continuous():
    """Given an approach under way (a 10 m step, mid-way: accelerating), when a sample
    elsewhere arrives, then the reference's position, velocity and acceleration carry on
    without a step (to a step's worth of jerk), so the tilts need not jump."""
    s = offboard.start(0, pose_ref((0.0, 0.0, 5.0), Q0), LIM)
    refs: list[Reference] = []
    for k in range(0, 6000):
        target = Target(1 if k < 700 else 2, (10.0, 0.0, 5.0) if k < 700 else (0.0, 8.0, 7.0),
                        Z, Z, Q0, Z)
        s, ref = offboard.advance(s, k * 2000, target, LIM)
        refs.append(ref)
    seam = refs[699:703]
    assert math.hypot(*seam[0].a_enu_m_s2) > 0.5  # it was accelerating
    for r0, r1 in itertools.pairwise(seam):
        assert math.dist(r0.a_enu_m_s2, r1.a_enu_m_s2) < 0.05
        assert math.dist(r0.v_enu_m_s, r1.v_enu_m_s) < 0.01
    assert math.dist(refs[-1].p_enu_m, (0.0, 8.0, 7.0)) < 1e-6
