"""SITL plant: rigid body, actuators, ground contact and disturbances (sitl.plant)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from common.config.scenario import DisturbanceTerm, load_scenario, load_vehicle
from fcu.control.allocation import hover_command
from sitl.disturbance import Disturbance
from sitl.plant import ActuatorCommand, Plant, PlantState, rotate, rotate_inv
from sitl.plant_kernels import derivative_kernel

ROOT = Path(__file__).resolve().parents[2]
ZERO6 = (0.0,) * 6


@pytest.fixture(scope="module")
def vehicle():
    return load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml")


@pytest.fixture(scope="module")
def hover(vehicle):
    return hover_command(vehicle)


def rot_matrix(q) -> np.ndarray:
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def run(plant: Plant, state: PlantState, cmd: ActuatorCommand, steps: int, check=None):
    for _ in range(steps):
        state = plant.step(state, cmd)
        if check is not None:
            check(state)
    return state


# ----------------------------------------------------------------------------------------
# Rigid body
# ----------------------------------------------------------------------------------------


def test_free_fall(vehicle):
    """Given rotors stopped and no ground, when falling 2 s, then z = z0 - g t^2 / 2."""
    plant = Plant(vehicle, ground_enabled=False)
    q0 = (math.cos(0.2), 0.0, math.sin(0.2), 0.0)
    s = plant.initial_state((1.0, 2.0, 100.0), on_ground=False, q_enu_flu=q0)
    g = vehicle.gravity_m_s2
    for _ in range(20):
        s = run(plant, s, ActuatorCommand(ZERO6, ZERO6), 100)
        t = s.time_us * 1e-6
        assert abs(s.p_enu_m[2] - (100.0 - 0.5 * g * t * t)) <= 1e-9
        assert abs(s.v_enu_m_s[2] + g * t) <= 1e-9
        assert s.p_enu_m[:2] == (1.0, 2.0)
        assert np.allclose(s.q_enu_flu, q0, rtol=0.0, atol=1e-15)
        assert not s.landed
    assert s.time_us == 2_000_000


def test_hover_equilibrium(vehicle, hover):
    """Given the hover command held and no ground, when 10 s pass, then nothing moves."""
    speeds, tilts = hover
    plant = Plant(vehicle, ground_enabled=False)
    s0 = plant.initial_state((0.0, 0.0, 5.0), on_ground=False, rotor_speed_rad_s=speeds,
                             tilt_rad=tilts)
    s = run(plant, s0, ActuatorCommand(speeds, tilts), 10_000)
    assert s.time_us == 10_000_000
    assert np.linalg.norm(np.subtract(s.p_enu_m, s0.p_enu_m)) < 1e-9
    assert np.allclose(s.q_enu_flu, (1.0, 0.0, 0.0, 0.0), rtol=0.0, atol=1e-12)
    assert np.linalg.norm(s.omega_flu_rad_s) < 1e-12


def test_torque_free_rotation_conserves_momentum_and_energy(vehicle):
    """Given a spin near the intermediate axis, when 10 s pass, then L_world and E hold."""
    plant = Plant(vehicle, ground_enabled=False)
    s = plant.initial_state((0.0, 0.0, 0.0), on_ground=False)._replace(
        omega_flu_rad_s=(0.1, 3.0, 0.1))
    inertia = np.array(vehicle.inertia_diag_kg_m2)

    def momentum(state):
        return rot_matrix(state.q_enu_flu) @ (inertia * np.array(state.omega_flu_rad_s))

    def energy(state):
        return 0.5 * float(np.sum(inertia * np.square(state.omega_flu_rad_s)))

    l0, e0 = momentum(s), energy(s)
    worst = {"L": 0.0, "E": 0.0, "q": 0.0}

    def check(state):
        worst["q"] = max(worst["q"], abs(math.sqrt(sum(c * c for c in state.q_enu_flu)) - 1))
        worst["L"] = max(worst["L"], float(np.linalg.norm(momentum(state) - l0)
                                           / np.linalg.norm(l0)))
        worst["E"] = max(worst["E"], abs(energy(state) - e0) / e0)

    s = run(plant, s, ActuatorCommand(ZERO6, ZERO6), 10_000, check)
    assert worst["q"] <= 1e-12
    assert worst["L"] <= 1e-8
    assert worst["E"] <= 1e-8
    # The body really tumbled (intermediate axis): omega moved far from its start.
    assert np.linalg.norm(np.subtract(s.omega_flu_rad_s, (0.1, 3.0, 0.1))) > 1.0


@pytest.mark.parametrize("ideal", [False, True])
def test_step_is_pure_function_of_state_and_command(vehicle, hover, ideal):
    """Given a used plant, when a state is stepped again, then the result equals a fresh one."""
    speeds, tilts = hover
    s_a = Plant(vehicle).initial_state((0.0, 0.0, 5.0), on_ground=False,
                                       rotor_speed_rad_s=speeds, tilt_rad=tilts)
    s_b = s_a._replace(rotor_speed_rad_s=(500.0,) * 6, tilt_rad=(0.3,) * 6,
                       omega_flu_rad_s=(0.1, -0.2, 0.3))
    cmd_a = ActuatorCommand(speeds, tilts)
    cmd_b = ActuatorCommand((1200.0,) * 6, (-0.5,) * 6)
    used = Plant(vehicle, ideal_actuators=ideal, ground_enabled=False)
    sequence = [(s_a, cmd_a), (s_b, cmd_b), (s_a, cmd_b), (s_b, cmd_a), (s_a, cmd_a)]
    for state, cmd in sequence * 2:
        fresh = Plant(vehicle, ideal_actuators=ideal, ground_enabled=False).step(state, cmd)
        assert used.step(state, cmd) == fresh


def test_energy_helper_counts_all_terms(vehicle):
    """Given a state, when energy() is read, then it is kinetic plus potential energy."""
    plant = Plant(vehicle)
    s = plant.initial_state((0.0, 0.0, 2.0), on_ground=False)._replace(
        v_enu_m_s=(1.0, 0.0, 0.0), omega_flu_rad_s=(0.0, 0.0, 1.0))
    m, g, jz = vehicle.mass_kg, vehicle.gravity_m_s2, vehicle.inertia_diag_kg_m2[2]
    assert plant.energy(s) == pytest.approx(0.5 * m + 0.5 * jz + 2.0 * m * g, rel=1e-15)


# ----------------------------------------------------------------------------------------
# Actuators
# ----------------------------------------------------------------------------------------


def test_rotor_lag_step_up_uses_tau_up(vehicle):
    """Given a step up, when tau_up has elapsed, then the rotor is at 63.2 % of the step."""
    plant = Plant(vehicle, dt_us=500, ground_enabled=False)
    assert vehicle.rotor_tau_up_s == 0.0125
    s = plant.initial_state((0.0, 0.0, 0.0), on_ground=False)
    s = run(plant, s, ActuatorCommand((1000.0,) * 6, ZERO6), 25)  # 12.5 ms
    for w in s.rotor_speed_rad_s:
        assert w == pytest.approx(1000.0 * (1.0 - math.exp(-1.0)), rel=1e-12)
        assert abs(w / 1000.0 - 0.632) < 1e-3


def test_rotor_lag_step_down_uses_tau_down(vehicle):
    """Given a step down, when tau_down has elapsed, then 36.8 % of the step remains."""
    plant = Plant(vehicle, dt_us=500, ground_enabled=False)
    s = plant.initial_state((0.0, 0.0, 0.0), on_ground=False, rotor_speed_rad_s=(1000.0,) * 6)
    half = run(plant, s, ActuatorCommand((200.0,) * 6, ZERO6), 25)  # tau_up: must not be there
    assert half.rotor_speed_rad_s[0] > 200.0 + 800.0 * math.exp(-1.0) + 50.0
    s = run(plant, half, ActuatorCommand((200.0,) * 6, ZERO6), 25)  # 25 ms = tau_down
    for w in s.rotor_speed_rad_s:
        assert w == pytest.approx(200.0 + 800.0 * math.exp(-1.0), rel=1e-12)


def test_actuators_at_matches_closed_form(vehicle):
    """Given a held command, when actuators_at is asked, then it uses the right lag."""
    plant = Plant(vehicle)
    cmd = ActuatorCommand((900.0, 100.0, 500.0, 500.0, 0.0, 1700.0), ZERO6)
    speeds, _ = plant.actuators_at((500.0,) * 6, ZERO6, cmd, 0.01)
    up, down = math.exp(-0.01 / vehicle.rotor_tau_up_s), math.exp(-0.01 / vehicle.rotor_tau_down_s)
    expected = (900 - 400 * up, 100 + 400 * down, 500.0, 500.0, 500 * down, 1700 - 1200 * up)
    assert np.allclose(speeds, expected, rtol=1e-14, atol=0.0)


def test_speed_command_clamped_at_max(vehicle):
    """Given a command above w_max, when held 1 s, then speeds settle at w_max, never above."""
    plant = Plant(vehicle, ground_enabled=False)
    s = plant.initial_state((0.0, 0.0, 0.0), on_ground=False)
    w_max = vehicle.rotor_speed_max_rad_s

    def check(state):
        assert max(state.rotor_speed_rad_s) <= w_max

    s = run(plant, s, ActuatorCommand((5000.0,) * 6, ZERO6), 1000, check)
    assert all(abs(w - w_max) < 1e-6 for w in s.rotor_speed_rad_s)
    s = run(plant, s, ActuatorCommand((-50.0,) * 6, ZERO6), 1000)
    assert all(0.0 <= w < 1e-6 for w in s.rotor_speed_rad_s)


def test_tilt_rate_limit(vehicle):
    """Given a tilt step, when it is followed, then the tilt moves at 4 rad/s and stops."""
    plant = Plant(vehicle, ground_enabled=False)
    assert vehicle.tilt_rate_max_rad_s == 4.0
    s = plant.initial_state((0.0, 0.0, 0.0), on_ground=False)
    cmd = ActuatorCommand(ZERO6, (1.0, -1.0, 0.2, -0.2, 3.0, 0.0))
    s = run(plant, s, cmd, 100)  # 0.1 s: at most 0.4 rad
    assert np.allclose(s.tilt_rad, (0.4, -0.4, 0.2, -0.2, 0.4, 0.0), atol=1e-12)
    s = run(plant, s, cmd, 700)
    assert np.allclose(s.tilt_rad, cmd.tilt_rad, atol=1e-12)


def test_ideal_actuators_follow_instantly(vehicle):
    """Given ideal actuators, when one step passes, then speeds and tilts equal the command."""
    plant = Plant(vehicle, ideal_actuators=True, ground_enabled=False)
    s = plant.initial_state((0.0, 0.0, 0.0), on_ground=False)
    cmd = ActuatorCommand((100.0, 200.0, 300.0, 400.0, 500.0, 600.0),
                          (1.0, -2.0, 3.0, 0.5, 0.0, -0.5))
    s = plant.step(s, cmd)
    assert s.rotor_speed_rad_s == cmd.rotor_speed_rad_s
    assert s.tilt_rad == cmd.tilt_rad


# ----------------------------------------------------------------------------------------
# Ground
# ----------------------------------------------------------------------------------------


def test_resting_on_ground_stays(vehicle):
    """Given a landed vehicle with rotors stopped, when 1 s passes, then it stays at z = 0."""
    plant = Plant(vehicle)
    s = plant.initial_state((0.0, 0.0, 0.0), on_ground=True)
    assert s.landed
    s = run(plant, s, ActuatorCommand(ZERO6, ZERO6), 1000)
    assert s.landed and s.p_enu_m == (0.0, 0.0, 0.0) and s.v_enu_m_s == (0.0, 0.0, 0.0)


def test_lift_off_with_margin(vehicle, hover):
    """Given hover speeds plus 5 %, when 1 s passes, then the vehicle lifts off the ground."""
    speeds, tilts = hover
    plant = Plant(vehicle, ideal_actuators=True)
    s = plant.initial_state((0.0, 0.0, 0.0), on_ground=True)
    s = run(plant, s, ActuatorCommand(tuple(1.05 * w for w in speeds), tilts), 1000)
    assert not s.landed
    assert s.p_enu_m[2] > 0.1 and s.v_enu_m_s[2] > 0.0


def test_below_hover_speed_stays_on_ground(vehicle, hover):
    """Given hover speeds minus 5 %, when 1 s passes, then the vehicle stays landed."""
    speeds, tilts = hover
    plant = Plant(vehicle, ideal_actuators=True)
    s = plant.initial_state((0.0, 0.0, 0.0), on_ground=True)
    s = run(plant, s, ActuatorCommand(tuple(0.95 * w for w in speeds), tilts), 1000)
    assert s.landed and s.p_enu_m[2] == 0.0


def test_drop_lands_on_ground(vehicle):
    """Given a drop from 1 m, when 1 s passes, then it rests on z = 0 and never below."""
    plant = Plant(vehicle)
    s = plant.initial_state((0.0, 0.0, 1.0), on_ground=False)
    assert not s.landed

    def check(state):
        assert state.p_enu_m[2] >= 0.0

    s = run(plant, s, ActuatorCommand(ZERO6, ZERO6), 1000, check)
    assert s.landed
    assert s.p_enu_m[2] == 0.0
    assert s.v_enu_m_s == (0.0, 0.0, 0.0) and s.omega_flu_rad_s == (0.0, 0.0, 0.0)


# ----------------------------------------------------------------------------------------
# Disturbances
# ----------------------------------------------------------------------------------------


def test_force_pulse_changes_velocity_by_impulse(vehicle, hover):
    """Given a hovering vehicle, when a 5 N x pulse acts 2 s, then dv_x = F t / m."""
    speeds, tilts = hover
    pulse = DisturbanceTerm("pulse", (5.0, 0.0, 0.0), start_s=1.0002, end_s=3.0002)
    plant = Plant(vehicle, ideal_actuators=True, ground_enabled=False,
                  disturbance=Disturbance((pulse,), ()))
    s = plant.initial_state((0.0, 0.0, 5.0), on_ground=False, rotor_speed_rad_s=speeds,
                            tilt_rad=tilts)
    cmd = ActuatorCommand(speeds, tilts)
    before = run(plant, s, cmd, 1000)  # t = 1 s, pulse not started
    assert np.linalg.norm(before.v_enu_m_s) < 1e-12
    after = run(plant, before, cmd, 2500)  # t = 3.5 s, pulse over
    expected = 5.0 * 2.0 / vehicle.mass_kg
    assert abs(after.v_enu_m_s[0] - expected) <= 1e-6
    assert abs(after.v_enu_m_s[1]) <= 1e-9 and abs(after.v_enu_m_s[2]) <= 1e-9
    assert np.allclose(after.q_enu_flu, (1.0, 0.0, 0.0, 0.0), rtol=0.0, atol=1e-12)


def test_sine_force_integrates_exactly(vehicle, hover):
    """Given a body x sine force while hovering, when 2 s pass, then v_x = A (1 - cos wT) / m w."""
    speeds, tilts = hover
    amp, omega = 3.0, 2.0
    term = DisturbanceTerm("sine", (amp, 0.0, 0.0), omega_rad_s=omega)
    plant = Plant(vehicle, ideal_actuators=True, ground_enabled=False,
                  disturbance=Disturbance((term,), ()))
    s = plant.initial_state((0.0, 0.0, 5.0), on_ground=False, rotor_speed_rad_s=speeds,
                            tilt_rad=tilts)
    s = run(plant, s, ActuatorCommand(speeds, tilts), 2000)
    expected = amp * (1.0 - math.cos(2.0 * omega)) / (vehicle.mass_kg * omega)
    assert abs(s.v_enu_m_s[0] - expected) <= 1e-9


def test_spin_up_lift_matches_rotor_lag(vehicle):
    """Given rotors spinning up from rest, when 0.1 s pass, then v_z integrates the lag."""
    plant = Plant(vehicle, dt_us=250, ground_enabled=False)  # RK4 error ~ (h / tau)^4
    c, tau = 1500.0, vehicle.rotor_tau_up_s
    s = plant.initial_state((0.0, 0.0, 5.0), on_ground=False)
    t = 0.1
    s = run(plant, s, ActuatorCommand((c,) * 6, ZERO6), 400)
    # f_z = sum c_f w^2 cos(beta_i), w(t) = c (1 - exp(-t / tau)) on every rotor
    lift = sum(vehicle.thrust_coeff * math.cos(b) for b in vehicle.arm_elevation_rad) * c * c
    integral = (t - 2.0 * tau * (1.0 - math.exp(-t / tau))
                + 0.5 * tau * (1.0 - math.exp(-2.0 * t / tau)))
    expected = lift * integral / vehicle.mass_kg - vehicle.gravity_m_s2 * t
    assert abs(s.v_enu_m_s[2] - expected) <= 1e-9 * (1.0 + abs(expected))
    assert np.allclose(s.v_enu_m_s[:2], (0.0, 0.0), atol=1e-12)


def test_force_disturbance_is_in_body_frame(vehicle):
    """Given a yawed vehicle, when a body x force acts, then it accelerates along body x."""
    yaw = 0.5 * math.pi
    q = (math.cos(0.5 * yaw), 0.0, 0.0, math.sin(0.5 * yaw))
    term = DisturbanceTerm("pulse", (5.0, 0.0, 0.0), start_s=0.0, end_s=10.0)
    plant = Plant(vehicle, ideal_actuators=True, ground_enabled=False,
                  disturbance=Disturbance((term,), ()))
    s = plant.initial_state((0.0, 0.0, 5.0), on_ground=False, q_enu_flu=q)
    s = run(plant, s, ActuatorCommand(ZERO6, ZERO6), 1000)
    v = s.v_enu_m_s
    assert abs(v[0]) <= 1e-9
    assert abs(v[1] - 5.0 / vehicle.mass_kg) <= 1e-9  # body x points north (ENU +y)


def test_disturbance_sine_and_pulse_profiles():
    """Given sine and pulse terms, when evaluated, then each term follows its profile."""
    sine = DisturbanceTerm("sine", (1.0, 2.0, 3.0), start_s=1.0, end_s=10.0,
                           omega_rad_s=0.5, phase_rad=0.3)
    pulse = DisturbanceTerm("pulse", (0.0, 0.0, -4.0), start_s=2.0, end_s=3.0)
    torque = DisturbanceTerm("sine", (0.1, 0.0, 0.0), omega_rad_s=2.0)
    d = Disturbance((sine, pulse), (torque,))
    assert d.active and not Disturbance().active
    assert Disturbance().wrench(5.0) == ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    for t in (0.0, 0.999, 1.0, 1.5, 2.0, 2.999, 3.0, 9.999, 10.0, 20.0):
        f, tau = d.wrench(t)
        k = math.sin(0.5 * t + 0.3) if 1.0 <= t < 10.0 else 0.0
        on = 1.0 if 2.0 <= t < 3.0 else 0.0
        assert f == pytest.approx((k, 2.0 * k, 3.0 * k - 4.0 * on), abs=1e-15)
        assert tau == pytest.approx((0.1 * math.sin(2.0 * t), 0.0, 0.0), abs=1e-15)


@pytest.mark.parametrize(("name", "force", "torque"), [
    ("case2_sine", lambda t: 5.0 * math.sin(0.2 * math.pi * t),
     lambda t: math.sin(0.2 * math.pi * t)),
    ("case2_irregular", lambda t: math.sin(0.2 * math.pi * t) + math.sin(0.3 * math.pi * t),
     lambda t: 0.2 * math.sin(0.2 * math.pi * t) + 0.2 * math.sin(0.3 * math.pi * t)),
    ("case2_impulse", lambda t: 5.0 if 20.0 <= t < 22.0 else 0.0,
     lambda t: 1.0 if 5.0 <= t < 7.0 else 0.0),
])
def test_shipped_disturbance_profiles(name, force, torque):
    """Given a shipped Case II scenario, when its disturbance is evaluated, then it matches."""
    sc = load_scenario(ROOT / "config/scenarios" / f"{name}.toml")
    d = Disturbance(sc.force_terms, sc.torque_terms)
    for t in np.linspace(0.0, 60.0, 241):
        f, tau = d.wrench(float(t))
        assert f == pytest.approx((force(t),) * 3, abs=1e-12)
        assert tau == pytest.approx((torque(t),) * 3, abs=1e-12)


# ----------------------------------------------------------------------------------------
# Exact actuator trajectory inside a step (tilt servos reaching their command mid-step)
# ----------------------------------------------------------------------------------------

TILT0 = (0.2, -0.1, 0.5, 0.0, -0.3, 0.1)
SPEED0 = (1000.0, 1050.0, 980.0, 1010.0, 1020.0, 990.0)


def reference_step(plant: Plant, s: PlantState, cmd: ActuatorCommand,
                   substeps: int = 2000) -> np.ndarray:
    """(p, v, q, w) one plant step after s, by `substeps` RK4 steps on the exact actuator
    trajectory (closed form from the step's start) plus the disturbance at absolute time."""
    h = plant.dt_us * 1e-6
    t0 = s.time_us * 1e-6
    hs = h / substeps

    def wrench(tau):
        speeds, tilts = plant.actuators_at(s.rotor_speed_rad_s, s.tilt_rad, cmd, tau)
        f, t = plant.rotor_wrench(speeds, tilts)
        df, dt = plant.disturbance.wrench(t0 + tau)
        return (f[0] + df[0], f[1] + df[1], f[2] + df[2], t[0] + dt[0], t[1] + dt[1],
                t[2] + dt[2])

    x = np.array([*s.p_enu_m, *s.v_enu_m_s, *s.q_enu_flu, *s.omega_flu_rad_s])
    for k in range(substeps):
        a = k * hs
        wa, wm, wb = wrench(a), wrench(a + 0.5 * hs), wrench(a + hs)
        k1 = np.array(derivative_kernel(plant.params, tuple(x), wa))
        k2 = np.array(derivative_kernel(plant.params, tuple(x + 0.5 * hs * k1), wm))
        k3 = np.array(derivative_kernel(plant.params, tuple(x + 0.5 * hs * k2), wm))
        k4 = np.array(derivative_kernel(plant.params, tuple(x + hs * k3), wb))
        x = x + hs / 6.0 * (k1 + 2.0 * (k2 + k3) + k4)
    return x


def tumbling_state(speeds=SPEED0, tilts=TILT0) -> PlantState:
    q = np.array([0.9, 0.2, -0.3, 0.25])
    q = tuple(float(c) for c in q / np.linalg.norm(q))
    return PlantState(12_345_000, (1.0, -2.0, 3.0), (0.5, -0.4, 0.3), q, (0.8, -1.1, 0.6),
                      speeds, tilts, False)


def increment_errors(plant: Plant, s: PlantState, cmd: ActuatorCommand) -> dict[str, float]:
    """Relative error of the step's increment of p, v, q and w against `reference_step`."""
    s1 = plant.step(s, cmd)
    x0 = np.array([*s.p_enu_m, *s.v_enu_m_s, *s.q_enu_flu, *s.omega_flu_rad_s])
    x1 = np.array([*s1.p_enu_m, *s1.v_enu_m_s, *s1.q_enu_flu, *s1.omega_flu_rad_s])
    d_ref = reference_step(plant, s, cmd) - x0
    d = x1 - x0
    parts = {"p": slice(0, 3), "v": slice(3, 6), "q": slice(6, 10), "w": slice(10, 13)}
    return {k: float(np.linalg.norm(d[sl] - d_ref[sl]) / np.linalg.norm(d_ref[sl]))
            for k, sl in parts.items()}


def mid_step_targets(plant: Plant, fractions) -> tuple[float, ...]:
    """Tilt commands that servo i reaches fractions[i] of the way through the step
    (a fraction above 1: still moving at the step's end; 0: already there)."""
    lim = plant.tilt_rate * plant.dt_us * 1e-6
    signs = (1.0, -1.0, 1.0, 1.0, -1.0, 1.0)
    return tuple(a + sg * f * lim for a, sg, f in zip(TILT0, signs, fractions, strict=True))


def test_servo_reaching_command_mid_step_is_integrated_exactly(vehicle):
    """Given one servo that reaches its command half-way through a step, when stepped, then
    the increment matches a 2000-substep integration of the exact actuator trajectory."""
    plant = Plant(vehicle, ground_enabled=False)
    cmd = ActuatorCommand((1000.0,) * 6, mid_step_targets(plant, (0.5, 0, 0, 0, 0, 0)))
    err = increment_errors(plant, tumbling_state(speeds=(1000.0,) * 6), cmd)
    # A single RK4 step across the kink is off by ~2e-4 in w and ~5e-5 in v.
    assert max(err.values()) <= 1e-9, err


def test_several_servo_kinks_with_moving_rotors_and_disturbance(vehicle):
    """Given servos reaching their commands at distinct instants (two at the same one), rotors
    spinning up and down and a time-varying disturbance, when stepped at t = 12.345 s, then the
    increment matches the reference integration at absolute time."""
    force = DisturbanceTerm("sine", (2.0, -1.0, 3.0), omega_rad_s=20.0, phase_rad=0.3)
    torque = DisturbanceTerm("sine", (0.3, 0.2, -0.1), omega_rad_s=15.0)
    plant = Plant(vehicle, ground_enabled=False, disturbance=Disturbance((force,), (torque,)))
    cmd = ActuatorCommand((1100.0, 950.0, 980.0, 1200.0, 1020.0, 900.0),
                          mid_step_targets(plant, (0.3, 0.55, 0.8, 3.0, 0.3, 0.0)))
    err = increment_errors(plant, tumbling_state(), cmd)
    assert max(err.values()) <= 1e-9, err


def test_step_splits_only_at_kinks(vehicle):
    """Given servos reaching their commands inside a step or not, when stepped, then the step
    takes one RK4 step per smooth piece: 1 with no kink, k + 1 with k (the compiled step
    reports how many it took)."""
    plant = Plant(vehicle, ground_enabled=False)
    s = tumbling_state()
    cases = [((0, 0, 0, 0, 0, 0), 0), ((2.0, 5.0, 0, 0, 1.5, 0), 0), ((0.5, 0, 0, 0, 0, 0), 1),
             ((0.3, 0.3, 0.7, 0, 2.0, 0), 2), ((0.1, 0.2, 0.3, 0.4, 0.5, 0.6), 6)]
    for fractions, kinks in cases:
        s1 = plant.step(s, ActuatorCommand(SPEED0, mid_step_targets(plant, fractions)))
        assert plant.last_rk4_steps == kinks + 1, fractions
    # A servo that has reached its command sits exactly on it: no kink in the next step.
    assert s1.tilt_rad == mid_step_targets(plant, (0.1, 0.2, 0.3, 0.4, 0.5, 0.6))
    plant.step(s1, ActuatorCommand(SPEED0, s1.tilt_rad))
    assert plant.last_rk4_steps == 1


def _drop(plant: Plant, steps: int, speed: float = 300.0) -> list[PlantState]:
    """A vehicle falling from 0.5 m, rolled 0.2 rad and moving sideways, rotors below
    hover, onto the ground and resting there: every state."""
    q = (math.cos(0.1), math.sin(0.1), 0.0, 0.0)
    s = plant.initial_state((0.0, 0.0, 0.5), on_ground=False, q_enu_flu=q,
                            rotor_speed_rad_s=(speed,) * 6)
    s = s._replace(v_enu_m_s=(0.4, 0.0, -1.0))
    out = [s]
    for _ in range(steps):
        out.append(plant.step(out[-1], ActuatorCommand((speed,) * 6, ZERO6)))
    return out


def test_a_touchdown_shows_in_the_specific_force(vehicle):
    """Given a vehicle falling onto the ground (inelastic contact: its velocity zeroed in one
    step), then the specific force the IMU is told, rotated to ENU plus gravity and
    integrated over the touchdown, gives the true velocity change: the contact's impulse
    (its velocity change over the step) is in the step where it happens; resting, the
    normal reaction (g up) is read; without the previous state no impulse is added."""
    plant = Plant(vehicle)
    states = _drop(plant, 600)
    hit = next(k for k, s in enumerate(states) if s.landed)
    assert 0 < hit < 500 and not states[hit - 1].landed
    dt = plant.dt_us * 1e-6
    dv = [0.0, 0.0, 0.0]
    for a, b in zip(states[hit - 50:hit + 50], states[hit - 49:hit + 51], strict=True):
        f = rotate(b.q_enu_flu, plant.specific_force_flu(b, a))
        for i in range(3):
            dv[i] += (f[i] - (0.0, 0.0, plant.g)[i]) * dt
    true = [states[hit + 50].v_enu_m_s[i] - states[hit - 50].v_enu_m_s[i] for i in range(3)]
    assert dv == pytest.approx(true, abs=0.02)
    assert abs(true[2]) > 0.9  # the impulse carries most of it
    impulse = plant.contact_dv_enu(states[hit - 1], states[hit])
    assert impulse == pytest.approx(tuple(-v for v in states[hit - 1].v_enu_m_s))
    f_hit = plant.specific_force_flu(states[hit], states[hit - 1])
    assert math.hypot(*f_hit) > 500.0  # about 1 m/s in 1 ms
    rest = states[hit + 10]
    assert plant.specific_force_flu(rest, states[hit + 9]) == pytest.approx(
        rotate_inv(rest.q_enu_flu, (0.0, 0.0, plant.g)))
    assert plant.specific_force_flu(states[hit]) == pytest.approx(
        rotate_inv(states[hit].q_enu_flu, (0.0, 0.0, plant.g)))
    assert plant.contact_dv_enu(states[hit], states[hit + 1]) == (0.0, 0.0, 0.0)
