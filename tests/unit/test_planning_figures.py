"""The planning computations' figures, to the bit: the mission check's stretching (a 500-item
mission's planned end, 2 m legs), OFFBOARD's approach plan and POSCTL's envelope fit. They
were taken from the planners before they were compiled and cached (benchmarks/
bench_planning.py times them); any change of a result, however small, shows here."""

from __future__ import annotations

import math
from pathlib import Path

from benchmarks.mission_envelope import fast_limits, mixed, waypoints
from common.config.scenario import load_vehicle
from fcu.control.dualquat import q_exp
from fcu.envelope import feasibility
from fcu.mission.codes import MAV_MISSION_ACCEPTED
from fcu.mission.executor import MissionExecutor
from fcu.mission.validation import check_mission
from fcu.modes import manual, offboard
from fcu.reference import approach
from fcu.stages import Reference

ROOT = Path(__file__).resolve().parents[2]
TILTED = load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml")
PLANAR = load_vehicle(ROOT / "config/vehicles/hexa_planar.toml")
ZERO = (0.0, 0.0, 0.0)
LEVEL = (1.0, 0.0, 0.0, 0.0)


def test_500_item_mission_is_planned_to_the_bit():
    """Given the 500 mixed items of benchmarks/mission_envelope.py on the tilted vehicle,
    then they are accepted and planned from the origin to end at the same instant to the
    bit, with the caches emptied first or not (equal paths share one scaling), at
    `fast_limits`' speeds."""
    items = mixed(500)
    limits = fast_limits(TILTED)
    for _ in range(2):
        assert check_mission(items, limits).result == MAV_MISSION_ACCEPTED
        ex = MissionExecutor(items, limits)
        ex.start(0.0, ZERO, LEVEL)
        assert ex.end_time_s == float.fromhex("0x1.d3dff8695efd9p+13")  # 14971.996 s
        assert ex.refusal() == ""
        feasibility.clear_caches()


def test_2m_legs_are_stretched_to_the_bit():
    """Given 2 m legs at 3.75 m/s (planned in 1 s), then they are stretched to 1.629 s
    (tilted) and 1.919 s (planar), the same to the bit."""
    for vehicle, leg in ((TILTED, "0x1.a11adf5563d03p+0"), (PLANAR, "0x1.eb2934655472dp+0")):
        ex = MissionExecutor(waypoints(3), fast_limits(vehicle))
        ex.start(0.0, (0.0, 2.0, 3.0), LEVEL)
        assert [t1 - t0 for _, t0, t1 in ex.schedule][1:] == [float.fromhex(leg)] * 2


def test_approach_plan_to_the_bit():
    """Given an OFFBOARD step of (8, -5, 2) m and 1.2 rad of yaw from a hover, then the
    approach takes the same duration to the bit, bounded by rotor 5."""
    ref = Reference((0.0, 0.0, 15.0), LEVEL, ZERO, ZERO, ZERO, ZERO)
    sp = approach.Setpoint((8.0, -5.0, 17.0), ZERO, ZERO, q_exp((0.0, 0.0, 1.2)), ZERO)
    plan = approach.plan(feasibility.envelope(TILTED), offboard.limits(manual.StickSettings()),
                         sp, offboard._offset(ref, sp))
    assert plan is not None and plan.fits
    assert plan.duration_s == float.fromhex("0x1.10b66e5c15d3dp+2")  # 4.261 s
    assert plan.coeffs[0, 0] == -8.0 and plan.coeffs[5, 0] == -1.2
    assert plan.excess is not None and (plan.excess.kind, plan.excess.number,
                                        plan.excess.sample) == ("rotor", 5, 54)
    assert plan.excess.ratio == 0.8431771172367268


def test_envelope_fit_to_the_bit():
    """Given POSCTL entered rolled 60 deg on the planar vehicle, then its accelerations are
    halved once and its jerk and yaw rate cut to the same values to the bit."""
    fit = manual.fit_envelope(manual.StickSettings(), PLANAR,
                              q_exp((math.radians(60.0), 0.0, 0.0)))
    assert (fit.acc_xy_m_s2, fit.acc_up_m_s2, fit.acc_down_m_s2) == (1.5, 1.5, 1.5)
    assert fit.jerk_m_s3 == float.fromhex("0x1.122c1ea006afcp+1")  # 2.142 m/s^3
    assert fit.yaw_rate_deg_s == float.fromhex("0x1.4744e59ab21dep+5")  # 40.9 deg/s
    assert fit.yaw_jerk_deg_s3 == 720.0
