"""PX4's modes (common/wire/modes.py) against pymavlink's own PX4 tables, and POSCTL's stick ->
set-point integration (fcu/modes/manual.py)."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink import mavutil

from common.config.scenario import load_vehicle
from common.wire.mavlink import MAV
from common.wire.modes import ALIASES, Mode, by_name, decode, decode_custom, names
from fcu.control.dualquat import q_angle, q_exp, q_mul
from fcu.edge.setpoint_wire import sticks_from_manual_control
from fcu.envelope.feasibility import envelope
from fcu.modes import manual
from fcu.modes.manual import (
    DEADZONE,
    LEAD_M,
    Sticks,
    StickSettings,
    advance,
    deflection,
    fit_envelope,
    heading_ned,
    stick_velocity,
)
from fcu.stages import Reference

M = MAV
ROOT = Path(__file__).resolve().parents[2]
VEHICLE = load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml")
FLOWN = {"LOITER": Mode.HOLD, "MISSION": Mode.MISSION, "TAKEOFF": Mode.TAKEOFF,
         "LAND": Mode.LAND, "RTL": Mode.RTL, "POSCTL": Mode.POSCTL, "OFFBOARD": Mode.OFFBOARD}


# ------------------------------------------------------------------ modes


@pytest.mark.parametrize("name", sorted(mavutil.px4_map))
def test_every_px4_name_as_mavproxy_sends_it(name):
    """Given each entry of pymavlink's PX4 table (what MAVProxy's `mode NAME` sends as
    DO_SET_MODE p1, p2, p3), then the FCU decodes the modes it flies to the right mode and the
    others (MANUAL, ACRO, ...) to None; p1 carries CUSTOM_MODE_ENABLED."""
    base, main, sub = mavutil.px4_map[name]
    assert base & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert decode(main, sub) is FLOWN.get(name)


@pytest.mark.parametrize("mode", list(Mode))
def test_heartbeat_encoding_names_the_mode_as_pymavlink_does(mode):
    """Given each mode's custom_mode in a PX4 HEARTBEAT, then pymavlink (MAVProxy's prompt,
    `mode_string_v10`) names it with PX4's name, and it decodes back to the mode."""
    hb = M.MAVLink_heartbeat_message(M.MAV_TYPE_HEXAROTOR, M.MAV_AUTOPILOT_PX4, 1,
                                     mode.custom_mode, M.MAV_STATE_STANDBY, 3)
    assert mavutil.mode_string_v10(hb) == mode.px4_name
    assert decode_custom(mode.custom_mode) is mode
    assert mavutil.px4_map[mode.px4_name][1:] == mode.value


def test_names_and_aliases():
    """Names are case-insensitive; LOITER is HOLD; QGC's Return and Position are accepted;
    modes this FCU does not fly are unknown."""
    assert Mode.LOITER is Mode.HOLD and by_name("loiter") is Mode.HOLD
    assert by_name("Hold") is Mode.HOLD and by_name(" rtl ") is Mode.RTL
    assert by_name("return") is Mode.RTL and by_name("position") is Mode.POSCTL
    for name in ("ACRO", "MANUAL", "STABILIZED", "ALTCTL", "", "AUTO"):
        assert by_name(name) is None
    assert set(names()) == {"HOLD", "LOITER", "MISSION", "OFFBOARD", "LAND", "TAKEOFF", "RTL",
                            "POSCTL"}
    assert all(by_name(n) is m for n, m in ALIASES.items())
    assert decode(4, 0) is None and decode(4, 7) is None and decode(2, 0) is None
    assert decode(3, 9) is Mode.POSCTL and decode(6, 3) is Mode.OFFBOARD  # sub ignored


# ------------------------------------------------------------------ sticks


def test_manual_control_axes():
    """x, y, r in -1000..1000, z 0..1000 with 500 at the centre (PX4); INT16_MAX = axis not
    given (centred); out-of-range values clamped."""
    assert sticks_from_manual_control(0, 0, 500, 0) == Sticks(0.0, 0.0, 0.0, 0.0)
    assert sticks_from_manual_control(1000, -500, 1000, 250) == Sticks(1.0, -0.5, 1.0, 0.25)
    assert sticks_from_manual_control(0, 0, 0, 0).up == -1.0
    assert sticks_from_manual_control(32767, 32767, 32767, 32767) == manual.CENTRED
    assert sticks_from_manual_control(-32768, 5000, -2000, 1500) == Sticks(-1.0, 1.0, -1.0, 1.0)


def test_dead_zone_and_full_deflection():
    assert deflection(DEADZONE) == 0.0 and deflection(-DEADZONE * 0.5) == 0.0
    assert deflection(1.0) == 1.0 and deflection(-1.0) == -1.0
    assert deflection(0.5) == pytest.approx((0.5 - DEADZONE) / (1 - DEADZONE))
    assert deflection(math.nan) == 0.0


def test_stick_velocity_follows_the_heading():
    """Forward is along the heading, right 90 deg clockwise from it; a diagonal is clipped
    to the full speed; up/down use their own speeds; yaw rate clockwise."""
    s = StickSettings()
    v, _ = stick_velocity(Sticks(forward=1.0), 0.0, s)
    assert v == pytest.approx((5.0, 0.0, 0.0))
    v, _ = stick_velocity(Sticks(forward=1.0), math.pi / 2, s)  # facing east
    assert v == pytest.approx((0.0, 5.0, 0.0), abs=1e-12)
    v, _ = stick_velocity(Sticks(right=1.0), 0.0, s)
    assert v == pytest.approx((0.0, 5.0, 0.0))
    v, _ = stick_velocity(Sticks(forward=1.0, right=1.0), 0.0, s)
    assert math.hypot(v[0], v[1]) == pytest.approx(5.0)
    assert stick_velocity(Sticks(up=1.0), 0.0, s)[0][2] == pytest.approx(-3.0)
    assert stick_velocity(Sticks(up=-1.0), 0.0, s)[0][2] == pytest.approx(1.5)
    assert stick_velocity(Sticks(yaw=1.0), 0.0, s)[1] == pytest.approx(math.radians(90))


def _fly(sticks_for, seconds: float, dt_us: int = 2000, q=(1.0, 0.0, 0.0, 0.0),
         s: StickSettings | None = None):
    """Integrate from rest at the origin; returns the set-points and references."""
    s = s or StickSettings()
    sp = manual.start(0, (0.0, 0.0, 0.0), q)
    out = []
    for k in range(1, round(seconds * 1e6 / dt_us) + 1):
        t_us = k * dt_us
        sp, ref = advance(sp, t_us, sticks_for(t_us * 1e-6), s, sp.p_enu_m)
        out.append((t_us * 1e-6, sp, ref))
    return out


@pytest.mark.parametrize("stick", [0.5, 1.0, -0.7])
def test_held_stick_moves_the_set_point_speed_times_time_then_holds(stick):
    """Given the forward stick held for 2 s then centred (facing north), then the set-point
    moves about V * 2 s north (the ramp up and the braking nearly cancel: within 2 %), stops
    and holds: no drift afterwards; the acceleration never exceeds its limit and changes at
    most at the jerk limit (no step), and the reference's velocity and acceleration are the
    derivatives of its position."""
    s = StickSettings()
    level_north = q_exp((0.0, 0.0, math.pi / 2))  # ENU/FLU: body x along the ENU y (north)
    assert heading_ned(level_north) == pytest.approx(0.0, abs=1e-12)
    out = _fly(lambda t: Sticks(forward=stick) if t <= 2.0 else manual.CENTRED, 6.0,
               q=level_north, s=s)
    speed = deflection(stick) * s.speed_xy_m_s
    end = out[-1][1].p_enu_m
    assert end[1] == pytest.approx(speed * 2.0, rel=0.02)  # ENU y = north
    assert abs(end[0]) < 1e-9 and abs(end[2]) < 1e-12
    stopped = [sp.p_enu_m for t, sp, _ in out if t > 5.0]
    assert max(math.dist(p, end) for p in stopped) < 1e-12  # holds
    assert max(abs(r.v_enu_m_s[1]) for _, _, r in out) == pytest.approx(abs(speed), rel=0.01)
    for (t0, sp0, r0), (t1, sp1, r1) in itertools.pairwise(out):
        assert math.hypot(*r1.a_enu_m_s2[:2]) <= s.acc_xy_m_s2 + 1e-9
        dt = t1 - t0
        assert abs(r1.a_enu_m_s2[1] - r0.a_enu_m_s2[1]) <= s.jerk_m_s3 * dt + 1e-9
        assert (r1.v_enu_m_s[1] - r0.v_enu_m_s[1]) / dt == pytest.approx(
            0.5 * (r0.a_enu_m_s2[1] + r1.a_enu_m_s2[1]), abs=1e-3)  # 1e-3: the snap to rest
        mean_v = r0.v_enu_m_s[1] + (2.0 * r0.a_enu_m_s2[1] + r1.a_enu_m_s2[1]) * dt / 6.0
        assert (sp1.p_enu_m[1] - sp0.p_enu_m[1]) / dt == pytest.approx(mean_v, abs=1e-9)


def test_throttle_climbs_and_yaw_turns_about_the_vertical():
    """Given throttle up 2 s and the yaw stick right 2 s, then the set-point climbs about
    speed_up * 2 s and turns clockwise by about yaw_rate * 2 s about the world vertical
    (within 5 %: the jerk-limited ramps nearly cancel), keeping a tilted entry attitude's
    roll and pitch; the body rate is the world yaw rate."""
    s = StickSettings()
    q0 = q_exp((0.3, -0.2, 0.0))
    out = _fly(lambda t: Sticks(up=1.0, yaw=1.0) if t <= 2.0 else manual.CENTRED, 5.0,
               q=q0, s=s)
    end = out[-1][1]
    assert end.p_enu_m[2] == pytest.approx(s.speed_up_m_s * 2.0, rel=0.05)
    assert end.yaw_ned_rad == pytest.approx(math.radians(s.yaw_rate_deg_s) * 2.0, rel=0.05)
    q_end = end.q_enu_flu
    expect = q_mul(q_exp((0.0, 0.0, -end.yaw_ned_rad)), q0)
    assert q_angle(q_mul(q_end, (expect[0], -expect[1], -expect[2], -expect[3]))) < 1e-12
    mid = next(ref for t, _, ref in out if t >= 1.5)
    w_world = manual.q_rotate(mid.q_enu_flu, mid.omega_flu_rad_s)
    assert w_world == pytest.approx((0.0, 0.0, -math.radians(s.yaw_rate_deg_s)), rel=0.01)


def test_set_point_never_leads_the_vehicle_by_more_than_the_lead():
    """Given a vehicle that does not move (held on the ground), when the stick pushes, then
    the set-point stays within LEAD_M of it."""
    sp = manual.start(0, (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))
    for k in range(1, 2000):
        sp, ref = advance(sp, k * 2000, Sticks(forward=1.0, up=-1.0), StickSettings(),
                          (0.0, 0.0, 0.0))
        assert math.dist(ref.p_enu_m, (0.0, 0.0, 0.0)) <= LEAD_M + 1e-12


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(*(st.floats(-1.5, 1.5) for _ in range(4)),
                          st.integers(0, 200_000)), min_size=1, max_size=30))
def test_any_stick_sequence_stays_within_the_limits(seq):
    """Given any sticks at any (even irregular) intervals, then the reference is finite, its
    accelerations within the limits and speeds within the full-stick speeds."""
    s = StickSettings()
    sp = manual.start(0, (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))
    t = 0
    for f, r, u, y, dt in seq:
        t += dt
        sp, ref = advance(sp, t, Sticks(f, r, u, y), s)
        assert all(math.isfinite(c) for c in (*ref.p_enu_m, *ref.v_enu_m_s, *ref.a_enu_m_s2,
                                              *ref.omega_flu_rad_s))
        assert math.hypot(*ref.a_enu_m_s2[:2]) <= s.acc_xy_m_s2 + 1e-9
        assert -s.acc_down_m_s2 - 1e-9 <= ref.a_enu_m_s2[2] <= s.acc_up_m_s2 + 1e-9
        assert math.hypot(*ref.v_enu_m_s[:2]) <= s.speed_xy_m_s + 1e-9
        assert -s.speed_down_m_s - 1e-9 <= ref.v_enu_m_s[2] <= s.speed_up_m_s + 1e-9


def _peak(settings_: StickSettings, q) -> float:
    """Rotor speed of the worst corner, as fit_envelope samples it (one yaw)."""
    env = envelope(VEHICLE)
    worst = 0.0
    for ang in [k * math.pi / 4 for k in range(8)]:
        for az in (settings_.acc_up_m_s2, -settings_.acc_down_m_s2):
            a = (settings_.acc_xy_m_s2 * math.cos(ang), settings_.acc_xy_m_s2 * math.sin(ang),
                 az)
            ref = Reference((0.0, 0.0, 0.0), q, (0.0, 0.0, 0.0), a, (0.0, 0.0, 0.0),
                            (0.0, 0.0, 0.0))
            worst = max(worst, float(env.speeds(ref).max()))
    return worst


def test_fit_envelope_halves_what_the_rotors_cannot_fly():
    """Given the defaults, then their accelerations fit the tilted hexarotor as they are;
    given 15 m/s^2 (MPC_ACC_* at their maximum) at a 40 deg roll, then the accelerations are
    halved until every corner fits the rotors' envelope, and not further for the rotors
    (the tilt servos may halve them again: `fit_envelope`)."""
    env = envelope(VEHICLE)
    level = (1.0, 0.0, 0.0, 0.0)
    fitted = fit_envelope(StickSettings(), VEHICLE, level)
    assert (fitted.acc_xy_m_s2, fitted.acc_up_m_s2, fitted.acc_down_m_s2) == (3.0, 3.0, 3.0)
    hard = StickSettings(acc_xy_m_s2=15.0, acc_up_m_s2=15.0, acc_down_m_s2=15.0)
    tilted = q_exp((math.radians(40), 0.0, 0.0))
    assert _peak(hard, tilted) > env.limit
    fitted = manual.fit_rotors(hard, VEHICLE, tilted)
    assert fit_envelope(hard, VEHICLE, tilted).acc_xy_m_s2 <= fitted.acc_xy_m_s2
    assert fitted.acc_xy_m_s2 < hard.acc_xy_m_s2
    assert _peak(fitted, tilted) <= env.limit
    doubled = StickSettings(acc_xy_m_s2=fitted.acc_xy_m_s2 * 2, acc_up_m_s2=fitted.acc_up_m_s2
                            * 2, acc_down_m_s2=fitted.acc_down_m_s2 * 2)
    assert not manual._fits(VEHICLE, tilted, doubled)
    assert fit_envelope(hard, None, tilted) == hard  # no vehicle: no check


@pytest.mark.parametrize("roll_rad", [0.0, 0.5, 1.0])
def test_fit_envelope_cuts_the_jerk_and_yaw_rate_to_what_the_tilt_servos_follow(roll_rad):
    """Given the defaults at a level or rolled attitude, then the jerk and yaw rate fitted
    keep the tilt rate they cause (gradient x rate, summed with the yaw jerk's) within the
    tilt servos' share at every corner, and they are not cut further than that needs."""
    q = q_exp((roll_rad, 0.0, 0.0))
    f = fit_envelope(StickSettings(), VEHICLE, q)
    g_acc, g_yaw, g_yaw_acc = manual._tilt_gradients(VEHICLE, q, f)
    need = g_acc * f.jerk_m_s3 + g_yaw * math.radians(f.yaw_rate_deg_s) + \
        g_yaw_acc * math.radians(f.yaw_jerk_deg_s3)
    assert need <= envelope(VEHICLE).tilt_limit * (1.0 + 1e-9)
    assert f.jerk_m_s3 == StickSettings().jerk_m_s3 or \
        g_acc * f.jerk_m_s3 == pytest.approx(manual.JERK_SHARE * envelope(VEHICLE).tilt_limit)


def test_mavproxy_module_sends_px4_map_entries_as_do_set_mode():
    """Given gcs.mavproxy_px4modes installed, when pymavlink's `set_mode` gets a px4_map
    entry (what MAVProxy's `mode NAME` passes), then DO_SET_MODE carries base, main and sub
    mode as floats (without it pymavlink puts the tuple into p1 and fails); uninstalled,
    pymavlink is as it was."""
    pytest.importorskip("MAVProxy")
    from gcs import mavproxy_px4modes

    original = mavutil.mavfile.set_mode
    conn = mavutil.mavlink_connection("udpout:127.0.0.1:9", source_system=255)
    try:
        sent = []
        conn.mav.command_long_send = lambda *args: sent.append(args)
        conn.messages["HEARTBEAT"] = M.MAVLink_heartbeat_message(
            M.MAV_TYPE_HEXAROTOR, M.MAV_AUTOPILOT_PX4, 1, 0, 3, 3)
        mavproxy_px4modes.install()
        mavproxy_px4modes.install()  # idempotent
        conn.set_mode(mavutil.px4_map["RTL"])
        assert sent[-1][2] == M.MAV_CMD_DO_SET_MODE
        base, main, sub = sent[-1][4:7]
        assert base & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED and decode(main, sub) is Mode.RTL
        conn.set_mode("LOITER")  # names still go through pymavlink's own path
        assert decode(*sent[-1][5:7]) is Mode.HOLD
    finally:
        mavproxy_px4modes.uninstall()
        conn.close()
    assert mavutil.mavfile.set_mode is original
