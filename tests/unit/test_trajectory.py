"""Trajectories (FigureEight, Hover) against finite differences; reference_twist; log_rate."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st

from common.config.scenario import load_scenario
from fcu.control.dualquat import (
    dq_from_pose,
    dq_log,
    q_angle,
    q_conj,
    q_exp,
    q_mul,
    q_rotate_inv,
)
from fcu.control.tracker import log_rate, reference_twist
from fcu.reference.trajectory import (
    FigureEight,
    FigureInfinity,
    Hover,
    figure_phase,
    make_trajectory,
    quintic,
)

ROOT = Path(__file__).resolve().parents[2]
SETTINGS = settings(max_examples=100, deadline=None)
H = 1e-4  # finite-difference step, s
KINKS = (10.0, 20.0, 140.0)  # acceleration (or jerk) steps of Case I


@pytest.fixture(scope="module")
def fig8() -> FigureEight:
    cfg = load_scenario(ROOT / "config/scenarios/case1_figure8.toml").trajectory
    return FigureEight(cfg)


# Times at least 0.01 s away from the kinks, in each of the four segments.
smooth_times = st.one_of(st.floats(0.001, 9.99), st.floats(10.01, 19.99),
                         st.floats(20.01, 139.99), st.floats(140.01, 159.99))


def central(f, t: float, h: float = H) -> np.ndarray:
    return (np.asarray(f(t + h), float) - np.asarray(f(t - h), float)) / (2.0 * h)


def assert_close(got, expected, abs_tol: float, rel_tol: float = 1e-6) -> None:
    got, expected = np.asarray(got, float), np.asarray(expected, float)
    err = np.max(np.abs(got - expected))
    assert err <= abs_tol + rel_tol * np.max(np.abs(expected)), (got, expected, err)


# ----------------------------------------------------------------------------------------
# FigureEight: derivatives
# ----------------------------------------------------------------------------------------


@SETTINGS
@given(smooth_times)
def test_velocity_and_acceleration_are_derivatives(fig8, t):
    """Given a smooth time, when p and v are differenced, then they match v and a."""
    ref = fig8.sample(t)
    assert_close(ref.v_enu_m_s, central(lambda s: fig8.sample(s).p_enu_m, t), 1e-7)
    assert_close(ref.a_enu_m_s2, central(lambda s: fig8.sample(s).v_enu_m_s, t), 1e-7)


@pytest.mark.parametrize("t", [3.0, 25.0, 60.0, 100.0])
def test_figure_is_moving_where_checked(fig8, t):
    """Given times inside the rise and the figure, when sampled, then v and a are not zero."""
    ref = fig8.sample(t)
    assert np.linalg.norm(ref.v_enu_m_s) > 1e-3
    assert np.linalg.norm(ref.a_enu_m_s2) > 1e-5


def body_rate_from_q(traj, t: float, h: float = H) -> np.ndarray:
    q = traj.sample(t).q_enu_flu
    dq = central(lambda s: traj.sample(s).q_enu_flu, t, h)
    return 2.0 * np.asarray(q_mul(q_conj(q), tuple(dq)))


@SETTINGS
@given(smooth_times)
def test_body_rate_matches_attitude_derivative(fig8, t):
    """Given a smooth time, when 2 q* dq/dt is formed, then it equals omega_flu (w = 0)."""
    ref = fig8.sample(t)
    w = body_rate_from_q(fig8, t)
    assert abs(w[0]) <= 1e-8
    assert_close(ref.omega_flu_rad_s, w[1:], 1e-7)
    assert_close(ref.omega_dot_flu_rad_s2,
                 central(lambda s: fig8.sample(s).omega_flu_rad_s, t), 1e-7)


def test_body_rate_nonzero_during_figure(fig8):
    """Given the figure phase, when sampled mid-way, then the body rate is not zero."""
    assert np.linalg.norm(fig8.sample(80.0).omega_flu_rad_s) > 0.1


@SETTINGS
@given(smooth_times)
def test_reference_twist_derivative(fig8, t):
    """Given a smooth time, when xi_d is differenced, then it equals xi_d_dot (both parts)."""
    _, xi_dot = reference_twist(fig8.sample(t))
    fd = central(lambda s: reference_twist(fig8.sample(s))[0], t)
    assert_close(xi_dot[3:], fd[3:], 1e-7)
    assert_close(xi_dot[:3], fd[:3], 1e-7)


@SETTINGS
@given(smooth_times)
def test_reference_twist_dual_part_is_body_velocity(fig8, t):
    """Given a reference, when xi_d is formed, then its parts are omega_d and R_d^T v_d."""
    ref = fig8.sample(t)
    xi, _ = reference_twist(ref)
    assert xi[:3] == ref.omega_flu_rad_s
    assert_close(xi[3:], q_rotate_inv(ref.q_enu_flu, ref.v_enu_m_s), 1e-14)


# ----------------------------------------------------------------------------------------
# FigureEight: continuity and fixed points
# ----------------------------------------------------------------------------------------


def test_attitude_continuous_through_figure_end(fig8):
    """Given t = 140 s, when sampled just before and after, then the attitude barely moves."""
    q1 = fig8.sample(140.0 - 1e-6).q_enu_flu
    q2 = fig8.sample(140.0 + 1e-6).q_enu_flu
    assert q_angle(q_mul(q_conj(q1), q2)) <= 1e-9
    assert fig8.phase(140.0) == (2.0 * math.pi, 0.0, 0.0)
    for t in (140.0, 145.0, 160.0):
        assert fig8.phase(t) == (2.0 * math.pi, 0.0, 0.0)
        q = fig8.sample(t).q_enu_flu
        assert_close(q, q_exp(tuple(2.0 * math.pi * c for c in (1.0, 2.0, 3.0))), 1e-15)
        assert fig8.sample(t).omega_flu_rad_s == (0.0, 0.0, 0.0)


def test_attitude_continuous_through_figure_start(fig8):
    """Given t = 20 s, when sampled just before and after, then the attitude barely moves."""
    q1 = fig8.sample(20.0 - 1e-6).q_enu_flu
    q2 = fig8.sample(20.0 + 1e-6).q_enu_flu
    assert q_angle(q_mul(q_conj(q1), q2)) <= 1e-9


@pytest.mark.parametrize("t", KINKS)
def test_position_and_velocity_continuous_at_kinks(fig8, t):
    """Given a kink time, when sampled 1e-9 s either side, then p and v are continuous."""
    before, after = fig8.sample(t - 1e-9), fig8.sample(t + 1e-9)
    assert_close(before.p_enu_m, after.p_enu_m, 1e-8)
    assert_close(before.v_enu_m_s, after.v_enu_m_s, 1e-7)


def test_starts_at_origin_at_rest(fig8):
    """Given t = 0, when sampled, then the reference is at the origin, level and at rest."""
    ref = fig8.sample(0.0)
    assert ref.p_enu_m == (0.0, 0.0, 0.0)
    assert ref.v_enu_m_s == (0.0, 0.0, 0.0)
    assert ref.a_enu_m_s2 == (0.0, 0.0, 0.0)
    assert ref.q_enu_flu == (1.0, 0.0, 0.0, 0.0)
    assert ref.omega_flu_rad_s == (0.0, 0.0, 0.0)


@pytest.mark.parametrize("t", [10.0, 12.5, 19.0, 140.0, 150.0, 160.0])
def test_holds_at_five_metres(fig8, t):
    """Given the hover segments, when sampled, then the reference sits at [0, 0, 5] at rest."""
    ref = fig8.sample(t)
    assert_close(ref.p_enu_m, (0.0, 0.0, 5.0), 1e-12)
    assert_close(ref.v_enu_m_s, (0.0, 0.0, 0.0), 1e-12)
    assert_close(ref.a_enu_m_s2, (0.0, 0.0, 0.0), 1e-12)


def fields(ref) -> np.ndarray:
    return np.concatenate([np.asarray(f, float) for f in ref])


@pytest.mark.parametrize("t", [0.0, *KINKS])
def test_breakpoints_take_the_right_hand_limit(fig8, t):
    """Given a breakpoint of Case I (rise start and end, figure start and end), when sampled
    at exactly that instant, then every field equals the sample 1 ns later: the value that
    holds over the control period starting there."""
    assert_close(fields(fig8.sample(t)), fields(fig8.sample(t + 1e-9)), 1e-8, 0.0)


def test_figure_start_carries_the_feed_forward(fig8):
    """Given t = 20 s exactly, then T'' = pi k^2 (not 0): the figure's acceleration and body
    rate derivative are there from the first control period, unlike just before 20 s."""
    k = math.pi / 120.0
    assert fig8.phase(20.0) == (0.0, 0.0, math.pi * k * k)
    at, before = fig8.sample(20.0), fig8.sample(20.0 - 1e-9)
    n = np.array([1.0, 2.0, 3.0])
    assert_close(at.omega_dot_flu_rad_s2, math.pi * k * k * n, 1e-15)
    assert_close(at.a_enu_m_s2, (10.0 * math.pi * k * k, 5.0 * math.pi * k * k, 0.0), 1e-15)
    assert np.max(np.abs(np.subtract(at.omega_dot_flu_rad_s2, before.omega_dot_flu_rad_s2))) > 2e-3
    assert at.v_enu_m_s == before.v_enu_m_s == (0.0, 0.0, 0.0)


def test_profiles_hold_outside_their_interval():
    """Given the shared profiles, then they hold before the start and from the end on, and
    the start sample is the inside formula (right-hand limit)."""
    assert quintic(-0.1) == (0.0, 0.0, 0.0) and quintic(1.0) == quintic(7.0) == (1.0, 0.0, 0.0)
    assert quintic(0.0) == (0.0, 0.0, 0.0)
    assert figure_phase(-1e-12, 10.0) == (0.0, 0.0, 0.0)
    assert figure_phase(0.0, 10.0) == (0.0, 0.0, math.pi ** 3 / 100.0)
    assert figure_phase(10.0, 10.0) == figure_phase(11.0, 10.0) == (2.0 * math.pi, 0.0, 0.0)


def test_figure_path_many_equals_sample():
    """Given a figure from a tilted start, when its path (flown in 1 s, arrays) is evaluated,
    then it equals the scalar samples of the same figure flown in 1 s, field by field."""
    q0 = q_exp((0.3, -0.5, 0.9))
    fig = FigureInfinity(2.0, 1.0, (2.0, -1.0, 3.0), (1.0, -2.0, 3.0), q0)
    sigma = np.linspace(0.0, 0.999, 37)
    many = fig.path(sigma)
    for i, s in enumerate(sigma):
        one = fig.sample(float(s))
        for f_many, f_one in zip(many, one, strict=True):
            assert_close([np.broadcast_to(c, sigma.shape)[i] for c in f_many], f_one, 1e-12)


def test_case1_uses_the_shared_figure(fig8):
    """Given Case I, then its figure is the shared FigureInfinity (identity start)."""
    assert isinstance(fig8.figure, FigureInfinity)
    assert fig8.figure.q0 is None and fig8.figure.duration == 120.0


def test_make_trajectory_dispatch(fig8):
    """Given the shipped scenarios, when make_trajectory, then the right class is built."""
    cfg = load_scenario(ROOT / "config/scenarios/case1_figure8.toml").trajectory
    assert isinstance(make_trajectory(cfg), FigureEight)
    hover_cfg = load_scenario(ROOT / "config/scenarios/case2_sine.toml").trajectory
    assert isinstance(make_trajectory(hover_cfg), Hover)


# ----------------------------------------------------------------------------------------
# Hover
# ----------------------------------------------------------------------------------------


@SETTINGS
@given(st.floats(0.0, 100.0))
def test_hover_is_constant(t):
    """Given a Hover, when sampled at any time, then pose is fixed and derivatives are zero."""
    q = (math.cos(0.3), 0.0, 0.0, math.sin(0.3))
    hover = Hover((1.0, -2.0, 3.0), q)
    ref = hover.sample(t)
    assert ref.p_enu_m == (1.0, -2.0, 3.0) and ref.q_enu_flu == q
    assert_close(central(lambda s: hover.sample(s).p_enu_m, t + 1.0), (0.0, 0.0, 0.0), 0.0)
    assert ref.v_enu_m_s == ref.a_enu_m_s2 == (0.0, 0.0, 0.0)
    assert ref.omega_flu_rad_s == ref.omega_dot_flu_rad_s2 == (0.0, 0.0, 0.0)
    xi, xi_dot = reference_twist(ref)
    assert xi == xi_dot == (0.0,) * 6


# ----------------------------------------------------------------------------------------
# log_rate along an analytic error motion
# ----------------------------------------------------------------------------------------


def axis_angle(axis, angle: float):
    s = math.sin(0.5 * angle)
    return (math.cos(0.5 * angle), s * axis[0], s * axis[1], s * axis[2])


class ErrorMotion:
    """q_e(t) = exp(a(t) u1) exp(b(t) u2), p_s(t) smooth: q_hat_e' = 1/2 q_hat_e xi_e.

    Body rate: omega = R(exp(b u2))^T a' u1 + b' u2; body velocity v = R(q_e)^T p_s'.
    """

    def __init__(self, u1, u2, a0, a1, b0, b1, freq, p0, p1) -> None:
        self.u1, self.u2 = np.asarray(u1), np.asarray(u2)
        self.a0, self.a1, self.b0, self.b1, self.f = a0, a1, b0, b1, freq
        self.p0, self.p1 = np.asarray(p0), np.asarray(p1)

    def angles(self, t):
        a = self.a0 + self.a1 * math.sin(self.f * t)
        b = self.b0 + self.b1 * math.cos(1.3 * self.f * t)
        da = self.a1 * self.f * math.cos(self.f * t)
        db = -1.3 * self.f * self.b1 * math.sin(1.3 * self.f * t)
        return a, b, da, db

    def q(self, t):
        a, b, _, _ = self.angles(t)
        return q_mul(axis_angle(self.u1, a), axis_angle(self.u2, b))

    def p(self, t):
        return self.p0 + self.p1 * np.array([math.sin(t), math.cos(2 * t), math.sin(0.5 * t)])

    def dp(self, t):
        return self.p1 * np.array([math.cos(t), -2 * math.sin(2 * t), 0.5 * math.cos(0.5 * t)])

    def qhat(self, t):
        return dq_from_pose(self.q(t), tuple(self.p(t)))

    def twist(self, t):
        _, b, da, db = self.angles(t)
        q2 = axis_angle(self.u2, b)
        w = np.asarray(q_rotate_inv(q2, tuple(da * self.u1))) + db * self.u2
        v = np.asarray(q_rotate_inv(self.q(t), tuple(self.dp(t))))
        return (*w, *v)


unit_axes = st.tuples(*(st.floats(-1.0, 1.0) for _ in range(3))).filter(
    lambda v: math.sqrt(sum(c * c for c in v)) > 0.1).map(
    lambda v: tuple(c / math.sqrt(sum(x * x for x in v)) for c in v))


def motions():
    return st.builds(
        ErrorMotion, unit_axes, unit_axes,
        st.floats(-1.5, 1.5), st.floats(0.0, 1.0), st.floats(-1.5, 1.5), st.floats(0.0, 1.0),
        st.floats(0.2, 3.0), st.tuples(*(st.floats(-5.0, 5.0) for _ in range(3))),
        st.tuples(*(st.floats(-3.0, 3.0) for _ in range(3))))


_NEAR_PI = ErrorMotion((1, 0, 0), (1, 0, 0), 1.42, 0.1, 1.5, 0.03, 1.0, (1, 2, 3), (1, 1, 1))
_TUMBLE = ErrorMotion((0, 0, 1), (0.6, 0.8, 0), 1.5, 0.5, 1.5, 0.5, 2.0, (4, -3, 2), (2, 2, 2))


@settings(max_examples=150, deadline=None)
@given(motions(), st.floats(0.0, 10.0))
@example(_NEAR_PI, 0.0)
@example(_NEAR_PI, 1.5)
@example(_TUMBLE, 0.7)
def test_log_rate_is_derivative_of_log(motion, t):
    """Given a smooth error motion, when log_rate is evaluated, then it is d/dt 2 ln q_hat_e."""
    h = 1e-5
    for s in (t - h, t, t + h):
        assume(q_angle(motion.q(s)) <= 3.05)
    got = np.asarray(log_rate(dq_log(motion.qhat(t)), motion.twist(t)))
    fd = central(lambda s: [2.0 * c for c in dq_log(motion.qhat(s))], t, h)
    err = np.abs(got - fd)
    assert np.max(err) <= 1e-6 * (1.0 + np.max(np.abs(fd))), (got, fd)


def test_log_rate_example_reaches_three_radians():
    """Given the near-pi example motion, when sampled, then it reaches an angle above 3 rad."""
    angles = [q_angle(_NEAR_PI.q(t)) for t in np.linspace(0.0, 6.3, 200)]
    assert 3.0 <= max(angles) <= 3.05


@pytest.mark.parametrize("theta", [1e-4, 1e-8, 0.5, 3.0])
def test_log_rate_continuous_across_series_branch(theta):
    """Given angles either side of the series switch, when log_rate, then no jump."""
    axis = np.array([2.0, -3.0, 6.0]) / 7.0
    xi = (0.3, -0.2, 0.5, 1.0, 2.0, -1.0)
    lo = log_rate((*(0.5 * theta * (1 - 1e-9) * axis), 0.1, 0.2, 0.3), xi)
    hi = log_rate((*(0.5 * theta * (1 + 1e-9) * axis), 0.1, 0.2, 0.3), xi)
    assert_close(lo, hi, 1e-12)
