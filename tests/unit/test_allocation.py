"""Allocation matrix, pseudo-inverse, Allocator (saturation, unwrapping, hold), hover."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from common.config.scenario import load_vehicle
from fcu.control.allocation import (
    Allocator,
    allocation_matrix,
    hover_command,
    pseudo_inverse,
    wrap_pi,
)
from sitl.plant import Plant

ROOT = Path(__file__).resolve().parents[2]
PRESETS = ("hexa_tilted", "hexa_planar")
SETTINGS = settings(max_examples=60, deadline=None)


def vehicle_path(name: str) -> Path:
    return ROOT / "config" / "vehicles" / f"{name}.toml"


@pytest.fixture(scope="module", params=PRESETS)
def preset(request):
    """(name, VehicleConfig, raw TOML dict) of a shipped preset."""
    path = vehicle_path(request.param)
    with path.open("rb") as fh:
        raw = tomllib.load(fh)
    return request.param, load_vehicle(path), raw


# ----------------------------------------------------------------------------------------
# Brute-force model (docs/model.md#geometry), written from the formulas, read from the raw TOML
# ----------------------------------------------------------------------------------------


def rz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def ry(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rx(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def model_wrench(raw: dict, speeds, tilts) -> np.ndarray:
    """[f; tau] = sum_i [F_i; r_i x F_i + Q_i] with F_i = c_f w^2 n_i, Q_i = -s_i c_d w^2 n_i."""
    cf, cd, arm = raw["thrust_coeff"], raw["drag_coeff"], raw["arm_length_m"]
    gammas = [math.radians(d) for d in raw["arm_azimuth_deg"]]
    f, tau = np.zeros(3), np.zeros(3)
    for gamma, beta, spin, w, alpha in zip(gammas, raw["arm_elevation_rad"], raw["spin"],
                                           speeds, tilts, strict=True):
        frame = rz(gamma) @ ry(beta)
        a_i = frame @ np.array([1.0, 0.0, 0.0])
        e_v = frame @ np.array([0.0, 0.0, 1.0])
        e_l = np.cross(a_i, e_v)  # where e_v goes after a +pi/2 turn about the arm
        n_i = math.cos(alpha) * e_v + math.sin(alpha) * e_l
        # The same direction by tilting the rotor frame about its arm (x) axis.
        assert np.allclose(n_i, frame @ rx(alpha) @ np.array([0.0, 0.0, 1.0]), atol=1e-14)
        force = cf * w * w * n_i
        drag = -spin * cd * w * w * n_i
        f += force
        tau += np.cross(arm * a_i, force) + drag
    return np.concatenate([f, tau])


def omega_vector(speeds, tilts) -> np.ndarray:
    out = []
    for w, a in zip(speeds, tilts, strict=True):
        out += [w * w * math.sin(a), w * w * math.cos(a)]
    return np.array(out)


speed_lists = st.lists(st.floats(0.0, 1700.0), min_size=6, max_size=6)
tilt_lists = st.lists(st.floats(-10.0, 10.0), min_size=6, max_size=6)


def rel_err(got, expected) -> float:
    got, expected = np.asarray(got, float), np.asarray(expected, float)
    return float(np.linalg.norm(got - expected) / max(np.linalg.norm(expected), 1e-300))


@SETTINGS
@given(speeds=speed_lists, tilts=tilt_lists)
def test_matrix_matches_brute_force_model(preset, speeds, tilts):
    """Given speeds and tilts, when A Omega is formed, then it equals the per-rotor sum."""
    _, vehicle, raw = preset
    expected = model_wrench(raw, speeds, tilts)
    assume(np.linalg.norm(expected) > 1e-6)
    got = allocation_matrix(vehicle) @ omega_vector(speeds, tilts)
    assert rel_err(got, expected) <= 1e-9


@SETTINGS
@given(speeds=speed_lists, tilts=tilt_lists)
def test_plant_wrench_matches_brute_force_model(preset, speeds, tilts):
    """Given speeds and tilts, when the plant sums its rotors, then it equals the model."""
    _, vehicle, raw = preset
    expected = model_wrench(raw, speeds, tilts)
    assume(np.linalg.norm(expected) > 1e-6)
    f, tau = Plant(vehicle).rotor_wrench(speeds, tilts)
    assert rel_err((*f, *tau), expected) <= 1e-9


EXPECTED_SINGULAR = {
    "hexa_planar": (2.449, 1.732, 1.732, 0.736, 0.520, 0.520),
    "hexa_tilted": (2.0, 2.0, 2.0, 0.601, 0.601, 0.601),
}


def test_singular_values(preset):
    """Given a preset, when A / c_f is decomposed, then its singular values are as expected."""
    name, vehicle, _ = preset
    sv = np.linalg.svd(allocation_matrix(vehicle) / vehicle.thrust_coeff, compute_uv=False)
    assert np.all(np.abs(sv - np.array(EXPECTED_SINGULAR[name])) < 5e-4), sv


def test_pseudo_inverse_is_right_inverse(preset):
    """Given A, when A A^+ is formed, then it is the 6 x 6 identity."""
    _, vehicle, _ = preset
    a = allocation_matrix(vehicle)
    assert a.shape == (6, 12)
    assert np.max(np.abs(a @ pseudo_inverse(a) - np.eye(6))) <= 1e-9


wrench_strategy = st.tuples(
    st.floats(-20.0, 20.0), st.floats(-20.0, 20.0), st.floats(-20.0, 20.0),
    st.floats(-3.0, 3.0), st.floats(-3.0, 3.0), st.floats(-3.0, 3.0))


@SETTINGS
@given(wrench_strategy)
def test_allocate_then_plant_reproduces_wrench(preset, delta):
    """Given a feasible wrench, when allocated and fed to the plant, then it is reproduced."""
    _, vehicle, _ = preset
    weight = vehicle.mass_kg * vehicle.gravity_m_s2
    force = (delta[0], delta[1], weight + delta[2])
    torque = delta[3:]
    alloc = Allocator(vehicle)
    result = alloc.allocate(force, torque)
    assume(not result.saturated and min(result.speed_rad_s) > 2.0 * alloc.hold_speed)
    f, tau = Plant(vehicle).rotor_wrench(result.speed_rad_s, result.tilt_rad)
    assert rel_err((*f, *tau), (*force, *torque)) <= 1e-9
    # The pseudo-inverse solution itself: A Omega = wrench.
    got = allocation_matrix(vehicle) @ np.asarray(result.omega_sq)
    assert rel_err(got, (*force, *torque)) <= 1e-9


@pytest.mark.parametrize(("name", "speed"), [("hexa_planar", 991.6), ("hexa_tilted", 1097.4)])
def test_hover_speeds(name, speed):
    """Given a preset, when hover_command, then every rotor spins at the hover speed."""
    speeds, tilts = hover_command(load_vehicle(vehicle_path(name)))
    assert len(speeds) == 6
    assert all(abs(w - speed) < 0.1 for w in speeds), speeds
    assert all(abs(wrap_pi(a)) < 1e-9 for a in tilts), tilts


# ----------------------------------------------------------------------------------------
# Unwrapping and wrap_pi
# ----------------------------------------------------------------------------------------


@pytest.mark.parametrize(("x", "expected"), [
    (math.pi, math.pi), (-math.pi, math.pi), (3.0 * math.pi, math.pi),
    (-3.0 * math.pi, math.pi), (5.0 * math.pi, math.pi), (0.0, 0.0), (-0.0, 0.0),
    (2.0 * math.pi, 0.0), (-2.0 * math.pi, 0.0), (0.5, 0.5), (-0.5, -0.5),
    (2.0 * math.pi + 0.5, 0.5), (-2.0 * math.pi - 0.5, -0.5),
])
def test_wrap_pi_edge_cases(x, expected):
    """Given edge angles, when wrapped, then the result is in (-pi, pi] as tabulated."""
    assert abs(wrap_pi(x) - expected) <= 1e-12


@settings(max_examples=300, deadline=None)
@given(st.floats(-1e4, 1e4))
def test_wrap_pi_range_and_congruence(x):
    """Given any angle, when wrapped, then it lies in [-pi, pi] and differs by 2 pi k."""
    y = wrap_pi(x)
    assert -math.pi <= y <= math.pi
    k = (x - y) / (2.0 * math.pi)
    assert abs(k - round(k)) <= 1e-12 * (1.0 + abs(x))


def rotating_wrenches(vehicle, phis):
    """Vertical weight and a lateral force of equal size rotating into each other."""
    weight = vehicle.mass_kg * vehicle.gravity_m_s2
    for phi in phis:
        yield (weight * math.sin(phi), 0.0, weight * math.cos(phi)), (0.0, 0.0, 0.0)


@pytest.mark.parametrize("turns", [(3, -5), (-4, 2)])
def test_tilt_unwrapping_through_pi_both_directions(preset, turns):
    """Given thrust directions rotating several turns, when allocated, then tilts unwrap."""
    _, vehicle, _ = preset
    alloc = Allocator(vehicle)
    steps_per_turn = 180
    phis = [0.0]
    for n in turns:
        k = abs(n) * steps_per_turn
        start = phis[-1]
        phis += [start + math.copysign(2.0 * math.pi, n) * j / steps_per_turn
                 for j in range(1, k + 1)]
    # Winding direction of each rotor's (lat, ver) ellipse: sign of det[o_vertical, o_lateral].
    o_ver = Allocator(vehicle).allocate((0.0, 0.0, 1.0), (0.0, 0.0, 0.0)).omega_sq
    o_lat = Allocator(vehicle).allocate((1.0, 0.0, 0.0), (0.0, 0.0, 0.0)).omega_sq
    dets = [o_ver[2 * i] * o_lat[2 * i + 1] - o_ver[2 * i + 1] * o_lat[2 * i]
            for i in range(vehicle.n_rotors)]
    winding = [0 if abs(d) < 1e-3 * max(map(abs, dets)) else (1 if d < 0 else -1) for d in dets]
    assert sum(1 for s in winding if s) >= 2

    tilts, raws = [tuple(alloc.tilt)], []
    for force, torque in rotating_wrenches(vehicle, phis[1:]):
        res = alloc.allocate(force, torque)
        assert not res.saturated
        tilts.append(res.tilt_rad)
        raws.append(res.tilt_raw_rad)
    tilts_a, raws_a = np.array(tilts), np.array(raws)
    steps = np.abs(np.diff(tilts_a, axis=0))
    assert np.max(steps) < math.pi
    assert np.max(steps) < 0.5  # continuous for a smooth input
    assert np.all(np.abs(raws_a) <= math.pi)
    mismatch = [abs(wrap_pi(t - r)) for t, r in zip(tilts_a[1:].ravel(), raws_a.ravel(),
                                                        strict=True)]
    assert max(mismatch) <= 1e-9
    # Net tilt after all turns: 2 pi per turn in each rotor's winding direction.
    net_turns = sum(turns)
    for i, s in enumerate(winding):
        change = tilts_a[-1, i] - tilts_a[0, i]
        if s:
            assert abs(change - 2.0 * math.pi * net_turns * s) <= 1e-6, (i, change)
        # Between the legs the tilt really left (-pi, pi] (that is what unwrapping is for).
    assert np.max(np.abs(tilts_a)) > 2.0 * math.pi


# ----------------------------------------------------------------------------------------
# Saturation and tilt hold
# ----------------------------------------------------------------------------------------


def test_saturation_for_huge_wrench(preset):
    """Given a huge wrench, when allocated, then speeds clip at w_max and the flag is set."""
    _, vehicle, _ = preset
    res = Allocator(vehicle).allocate((3000.0, -2000.0, 10000.0), (50.0, 50.0, 50.0))
    assert res.saturated
    assert max(res.speed_rad_s) == vehicle.rotor_speed_max_rad_s
    assert all(0.0 <= w <= vehicle.rotor_speed_max_rad_s for w in res.speed_rad_s)
    # The raw solution really exceeded w_max somewhere.
    om = np.asarray(res.omega_sq)
    assert np.max(np.hypot(om[0::2], om[1::2])) > vehicle.rotor_speed_max_rad_s ** 2


def test_no_saturation_in_hover(preset):
    """Given the hover wrench, when allocated, then the flag is clear."""
    _, vehicle, _ = preset
    weight = vehicle.mass_kg * vehicle.gravity_m_s2
    assert not Allocator(vehicle).allocate((0.0, 0.0, weight), (0.0, 0.0, 0.0)).saturated


def test_tilt_held_below_hold_speed(preset):
    """Given tilts set by a lateral wrench, when a zero wrench follows, then tilts are held."""
    _, vehicle, _ = preset
    alloc = Allocator(vehicle)
    first = alloc.allocate((30.0, 20.0, 10.0), (0.0, 0.0, 0.5))
    assert max(abs(a) for a in first.tilt_rad) > 0.1
    second = alloc.allocate((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    assert second.speed_rad_s == (0.0,) * 6
    assert second.tilt_rad == first.tilt_rad
    assert not second.saturated


def test_initial_tilt_held_for_zero_wrench(preset):
    """Given an initial tilt, when a zero wrench is allocated, then that tilt is returned."""
    _, vehicle, _ = preset
    initial = (0.1, -0.2, 0.3, 7.0, -7.0, 0.0)
    res = Allocator(vehicle, initial).allocate((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    assert res.tilt_rad == initial


def test_tilt_held_only_for_slow_rotors(preset):
    """Given a high hold threshold, when a small wrench is allocated, then slow rotors hold."""
    _, vehicle, _ = preset
    alloc = Allocator(vehicle, (1.0,) * 6, hold_speed_rad_s=50.0)
    res = alloc.allocate((0.0, 0.0, 1e-3), (0.0, 0.0, 0.0))  # speeds ~ 6 rad/s
    assert max(res.speed_rad_s) < 50.0
    assert res.tilt_rad == (1.0,) * 6
    res = alloc.allocate((0.0, 0.0, 40.0), (0.0, 0.0, 0.0))
    assert min(res.speed_rad_s) > 50.0
    assert all(abs(wrap_pi(t - r)) < 1e-12 for t, r in zip(res.tilt_rad, res.tilt_raw_rad,
                                                           strict=True))
