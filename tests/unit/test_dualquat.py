"""Property tests of the quaternion / dual-quaternion algebra in fcu.control.dualquat."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st

from fcu.control.dualquat import (
    DQ_IDENTITY,
    dq_ad,
    dq_conj,
    dq_exp,
    dq_from_pose,
    dq_log,
    dq_mul,
    dq_norm,
    dq_position_body,
    dq_position_world,
    dq_to_pose,
    dual_cross,
    gain_dot,
    q_angle,
    q_conj,
    q_exp,
    q_log,
    q_mul,
    q_norm,
)

SETTINGS = settings(max_examples=150, deadline=None)

# ----------------------------------------------------------------------------------------
# Strategies and independent reference helpers
# ----------------------------------------------------------------------------------------

_component = st.floats(-1.0, 1.0, allow_nan=False, allow_infinity=False)


@st.composite
def unit_quats(draw):
    """A unit quaternion: 4 bounded floats normalised, near-zero norms rejected."""
    raw = draw(st.tuples(_component, _component, _component, _component))
    n = math.sqrt(sum(c * c for c in raw))
    assume(n > 1e-3)
    return tuple(c / n for c in raw)


positions = st.tuples(*(st.floats(-50.0, 50.0, allow_nan=False) for _ in range(3)))
vec_components = st.floats(-10.0, 10.0, allow_nan=False)
dual_vecs = st.tuples(*(vec_components for _ in range(6)))


@st.composite
def unit_dual_quats(draw):
    """(q_hat, q, p_s) with q_hat built from a random pose."""
    q = draw(unit_quats())
    p = draw(positions)
    return dq_from_pose(q, p), q, p


@st.composite
def unit_axes(draw):
    raw = draw(st.tuples(_component, _component, _component))
    n = math.sqrt(sum(c * c for c in raw))
    assume(n > 1e-3)
    return tuple(c / n for c in raw)


def rot_matrix(q) -> np.ndarray:
    """R(q) from the textbook matrix formula (independent of the code under test)."""
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def axis_angle_quat(axis, angle: float):
    s = math.sin(0.5 * angle)
    return (math.cos(0.5 * angle), s * axis[0], s * axis[1], s * axis[2])


def close(a, b, tol: float) -> bool:
    return bool(np.max(np.abs(np.asarray(a, float) - np.asarray(b, float))) <= tol)


def pure_dq(v):
    """The pure dual quaternion (0, v_r) + eps (0, v_d) of a dual vector."""
    return (0.0, v[0], v[1], v[2], 0.0, v[3], v[4], v[5])


# ----------------------------------------------------------------------------------------
# Products and norms
# ----------------------------------------------------------------------------------------


@SETTINGS
@given(unit_quats(), unit_quats())
def test_q_mul_keeps_unit_norm(a, b):
    """Given two unit quaternions, when multiplied, then the product has unit norm."""
    assert abs(q_norm(q_mul(a, b)) - 1.0) <= 1e-12


@SETTINGS
@given(unit_quats(), unit_quats())
def test_q_mul_composes_rotations(a, b):
    """Given two unit quaternions, when multiplied, then R(a b) = R(a) R(b)."""
    assert close(rot_matrix(q_mul(a, b)), rot_matrix(a) @ rot_matrix(b), 1e-12)


@SETTINGS
@given(unit_dual_quats(), unit_dual_quats())
def test_dq_mul_keeps_unit_dual_norm(a, b):
    """Given two unit dual quaternions, when multiplied, then dq_norm is (1, 0)."""
    (qa, _, pa), (qb, _, pb) = a, b
    r, d = dq_norm(dq_mul(qa, qb))
    scale = 1.0 + np.linalg.norm(pa) + np.linalg.norm(pb)
    assert abs(r - 1.0) <= 1e-12
    assert abs(d) <= 1e-12 * scale


@SETTINGS
@given(unit_dual_quats(), st.floats(0.5, 3.0), st.floats(-2.0, 2.0))
def test_dq_norm_of_non_unit_dual_quaternion(a, scale, lam):
    """Given s (q_hat + eps lam q), when dq_norm is read, then it is (s, s lam)."""
    qh, q, p = a
    b = tuple(scale * c for c in (*q, *(d + lam * r for d, r in zip(qh[4:], q, strict=True))))
    r, d = dq_norm(b)
    assert abs(r - scale) <= 1e-12 * scale
    assert abs(d - scale * lam) <= 1e-12 * scale * (1.0 + np.linalg.norm(p))


@SETTINGS
@given(unit_dual_quats(), unit_dual_quats())
def test_dq_mul_composes_poses(a, b):
    """Given poses a and b, when their dual quaternions multiply, then the pose composes."""
    (qa_hat, qa, pa), (qb_hat, qb, pb) = a, b
    q, p = dq_to_pose(dq_mul(qa_hat, qb_hat))
    expected_p = np.asarray(pa) + rot_matrix(qa) @ np.asarray(pb)
    assert close(q, q_mul(qa, qb), 1e-15)
    assert close(p, expected_p, 1e-12 * (1.0 + np.linalg.norm(expected_p) + np.linalg.norm(pb)))


@SETTINGS
@given(unit_dual_quats())
def test_dq_conj_is_inverse(a):
    """Given a unit dual quaternion, when multiplied by its conjugate, then identity results."""
    qh, _, p = a
    scale = 1e-12 * (1.0 + np.linalg.norm(p))
    assert close(dq_mul(qh, dq_conj(qh)), DQ_IDENTITY, scale)
    assert close(dq_mul(dq_conj(qh), qh), DQ_IDENTITY, scale)


# ----------------------------------------------------------------------------------------
# Pose conversions
# ----------------------------------------------------------------------------------------


@SETTINGS
@given(unit_quats(), positions)
def test_pose_round_trip(q, p):
    """Given a pose, when converted to a dual quaternion and back, then it is unchanged."""
    q2, p2 = dq_to_pose(dq_from_pose(q, p))
    assert q2 == q
    assert close(p2, p, 1e-12 * (1.0 + np.linalg.norm(p)))


@SETTINGS
@given(unit_quats(), positions)
def test_dual_part_is_half_p_s_q_and_half_q_p_b(q, p):
    """Given a pose, when built, then d = 1/2 p_s q = 1/2 q p_b with p_b = R^T p_s."""
    qh = dq_from_pose(q, p)
    d = qh[4:]
    p_b = rot_matrix(q).T @ np.asarray(p)
    left = q_mul((0.0, *p), q)
    right = q_mul(q, (0.0, *p_b))
    tol = 1e-12 * (1.0 + np.linalg.norm(p))
    assert close(d, [0.5 * c for c in left], tol)
    assert close(d, [0.5 * c for c in right], tol)


@SETTINGS
@given(unit_quats(), positions)
def test_position_body_is_rotated_world_position(q, p):
    """Given a pose, when reading dq_position_body, then it equals R(q)^T p_s."""
    qh = dq_from_pose(q, p)
    expected = rot_matrix(q).T @ np.asarray(p)
    assert close(dq_position_body(qh), expected, 1e-12 * (1.0 + np.linalg.norm(p)))
    assert close(dq_position_world(qh), p, 1e-12 * (1.0 + np.linalg.norm(p)))


# ----------------------------------------------------------------------------------------
# Exponential and logarithm
# ----------------------------------------------------------------------------------------


@SETTINGS
@given(unit_dual_quats())
def test_dq_exp_of_log_up_to_sign(a):
    """Given any unit dual quaternion, when exp(ln q_hat) is formed, then it is +-q_hat."""
    qh, _, p = a
    back = dq_exp(dq_log(qh))
    tol = 1e-12 * (1.0 + np.linalg.norm(p))
    assert close(back, qh, tol) or close(back, [-c for c in qh], tol)


@SETTINGS
@given(unit_dual_quats())
@example((dq_from_pose((0.0, 1.0, 0.0, 0.0), (1.0, 2.0, 3.0)), None, (1.0, 2.0, 3.0)))
def test_dq_exp_of_log_exact_for_nonnegative_scalar(a):
    """Given q_hat with scalar part >= 0, when exp(ln q_hat) is formed, then it is q_hat."""
    qh, _, p = a
    if qh[0] < 0.0:
        qh = tuple(-c for c in qh)
    back = dq_exp(dq_log(qh))
    assert close(back, qh, 1e-12 * (1.0 + np.linalg.norm(p)))


@SETTINGS
@given(unit_quats())
def test_q_exp_of_log(q):
    """Given a unit quaternion, when q_exp(q_log(q)) is formed, then it is q (w >= 0) or -q."""
    back = q_exp(q_log(q))
    expected = q if q[0] >= 0.0 else tuple(-c for c in q)
    assert close(back, expected, 1e-12)
    assert back[0] >= -1e-15


@SETTINGS
@given(st.tuples(*(st.floats(-3.1, 3.1, allow_nan=False) for _ in range(3))))
def test_q_log_of_exp(r):
    """Given a rotation vector of angle < pi, when q_log(q_exp(r)) is formed, then it is r."""
    assume(np.linalg.norm(r) < math.pi - 1e-3)
    assert close(q_log(q_exp(r)), r, 1e-12 * (1.0 + np.linalg.norm(r)))


@SETTINGS
@given(unit_dual_quats())
def test_log_invariant_under_sign_flip(a):
    """Given q_hat with angle below pi - 1e-6, when negated, then ln q_hat is unchanged."""
    qh, q, p = a
    assume(q_angle(q) < math.pi - 1e-6)
    neg = tuple(-c for c in qh)
    assert close(dq_log(neg), dq_log(qh), 1e-13 * (1.0 + np.linalg.norm(p)))
    assert close(q_log(tuple(-c for c in q)), q_log(q), 1e-13)


@SETTINGS
@given(unit_axes(), st.floats(-15.0, -4.0))
@example((1.0, 0.0, 0.0), -15.0)
@example((0.0, 0.0, 1.0), -4.0)
@example((0.6, 0.0, 0.8), math.log10(2e-9))
def test_q_log_small_angles(axis, log10_angle):
    """Given angles 1e-15..1e-4, when q_log of the exact quaternion, then theta n to 1e-12."""
    angle = 10.0 ** log10_angle
    expected = np.asarray(axis) * angle
    got = np.asarray(q_log(axis_angle_quat(axis, angle)))
    assert np.linalg.norm(got - expected) <= 1e-12 * angle
    back = np.asarray(q_exp(tuple(expected)))
    assert close(back, axis_angle_quat(axis, angle), 1e-12 * angle)


@SETTINGS
@given(unit_axes(), st.sampled_from([1e-9, 1e-7, 0.0, -1e-9, -1e-7]))
def test_q_log_near_pi(axis, offset):
    """Given angles near pi, when q_log is formed, then the angle is right and |log| <= pi."""
    angle = math.pi - offset
    log = np.asarray(q_log(axis_angle_quat(axis, angle)))
    norm = float(np.linalg.norm(log))
    # Strictly below pi for angles below pi; at or past pi, rounding of n may add an ulp.
    assert norm <= (math.pi if offset > 0.0 else math.pi + 2e-15)
    # Beyond pi the shortest path is the opposite axis with angle 2 pi - angle.
    expected_angle = angle if angle <= math.pi else 2.0 * math.pi - angle
    assert abs(norm - expected_angle) <= 1e-12
    sign = 1.0 if offset >= 0.0 else -1.0
    assert close(log, sign * expected_angle * np.asarray(axis), 1e-12)
    assert abs(q_angle(axis_angle_quat(axis, angle)) - expected_angle) <= 1e-12


@pytest.mark.parametrize(("lo", "hi"), [(1e-10, 1e-7), (1e-7, 1e-5), (1e-5, 1e-3)])
def test_log_and_exp_continuous_across_small_angle_branches(lo, hi):
    """Given a dense sweep of small angles, when log and exp are formed, then no jump."""
    axis = np.array([2.0, -3.0, 6.0]) / 7.0
    angles = np.geomspace(lo, hi, 3001)
    logs = np.array([q_log(axis_angle_quat(axis, t)) for t in angles])
    exps = np.array([q_exp(tuple(axis * t)) for t in angles])
    exact = np.array([axis_angle_quat(axis, t) for t in angles])
    d_log = np.diff(logs, axis=0)
    d_expected = np.diff(angles)[:, None] * axis
    assert np.max(np.linalg.norm(d_log - d_expected, axis=1) / np.diff(angles)) <= 1e-6
    assert np.max(np.linalg.norm(logs - angles[:, None] * axis, axis=1) / angles) <= 1e-12
    d_exp = np.diff(exps, axis=0) - np.diff(exact, axis=0)
    assert np.max(np.linalg.norm(d_exp, axis=1) / np.diff(angles)) <= 1e-6


# ----------------------------------------------------------------------------------------
# Adjoint, dual cross product, gains
# ----------------------------------------------------------------------------------------


def _ad_scale(p, v) -> float:
    return 1e-12 * (1.0 + np.linalg.norm(p)) * (1.0 + np.linalg.norm(v))


@SETTINGS
@given(unit_dual_quats(), unit_dual_quats(), dual_vecs)
def test_ad_is_homomorphism(a, b, v):
    """Given a, b and v, when Ad(a b) v vs Ad(a)(Ad(b) v), then they are equal."""
    (qa, _, pa), (qb, _, pb) = a, b
    left = dq_ad(dq_mul(qa, qb), v)
    right = dq_ad(qa, dq_ad(qb, v))
    tol = 10 * _ad_scale(pa, v) * (1.0 + np.linalg.norm(pb))
    assert close(left, right, tol)


@SETTINGS
@given(unit_dual_quats(), dual_vecs)
def test_ad_of_conjugate_inverts(a, v):
    """Given a and v, when Ad(a*) is applied after Ad(a), then v is recovered."""
    qa, _, p = a
    tol = 10 * _ad_scale(p, v) * (1 + np.linalg.norm(p))
    assert close(dq_ad(dq_conj(qa), dq_ad(qa, v)), v, tol)
    assert close(dq_ad(qa, dq_ad(dq_conj(qa), v)), v, tol)


@SETTINGS
@given(unit_dual_quats(), unit_quats(), dual_vecs)
def test_ad_preserves_norms(a, q, v):
    """Given Ad, when applied, then |real| is kept; for a pure rotation |dual| is kept too."""
    qa, _, p = a
    out = dq_ad(qa, v)
    assert abs(np.linalg.norm(out[:3]) - np.linalg.norm(v[:3])) <= _ad_scale(p, v)
    rot = dq_from_pose(q, (0.0, 0.0, 0.0))
    out_r = dq_ad(rot, v)
    assert abs(np.linalg.norm(out_r[:3]) - np.linalg.norm(v[:3])) <= _ad_scale(0.0, v)
    assert abs(np.linalg.norm(out_r[3:]) - np.linalg.norm(v[3:])) <= _ad_scale(0.0, v)


@SETTINGS
@given(unit_dual_quats(), dual_vecs)
def test_ad_matches_literal_product(a, v):
    """Given a and v, when a (0,v_r)+eps(0,v_d) a* is multiplied out, then it equals dq_ad."""
    qa, _, p = a
    literal = dq_mul(dq_mul(qa, pure_dq(v)), dq_conj(qa))
    tol = 10 * _ad_scale(p, v)
    assert abs(literal[0]) <= tol and abs(literal[4]) <= tol  # still a pure dual quaternion
    expected = (*literal[1:4], *literal[5:8])
    assert close(dq_ad(qa, v), expected, tol)


@SETTINGS
@given(dual_vecs, dual_vecs)
def test_dual_cross_is_half_commutator(a, b):
    """Given pure dual quaternions a, b, when 1/2 (a b - b a), then it equals dual_cross."""
    ab = dq_mul(pure_dq(a), pure_dq(b))
    ba = dq_mul(pure_dq(b), pure_dq(a))
    half = [0.5 * (x - y) for x, y in zip(ab, ba, strict=True)]
    assert abs(half[0]) <= 1e-12 and abs(half[4]) <= 1e-12
    assert close(dual_cross(a, b), (*half[1:4], *half[5:8]), 1e-12)


@SETTINGS
@given(st.tuples(*(vec_components for _ in range(3))),
       st.tuples(*(vec_components for _ in range(3))), dual_vecs)
def test_gain_dot_per_part(k_r, k_d, v):
    """Given diagonal gains and v, when k_hat . v_hat, then K_r v_r + eps K_d v_d (eq. 3)."""
    out = gain_dot(k_r, k_d, v)
    expected = (*(np.diag(k_r) @ np.asarray(v[:3])), *(np.diag(k_d) @ np.asarray(v[3:])))
    assert close(out, expected, 0.0)


def test_gain_dot_keeps_parts_apart():
    """Given gains that differ per part, when applied, then each part uses its own gain."""
    out = gain_dot((1.0, 2.0, 3.0), (10.0, 20.0, 30.0), (1.0, 1.0, 1.0, 1.0, 1.0, 1.0))
    assert out == (1.0, 2.0, 3.0, 10.0, 20.0, 30.0)


def test_identity_constants():
    """Given the identity constants, when logged, then the log is zero."""
    assert dq_log(DQ_IDENTITY) == (0.0,) * 6
    assert dq_norm(DQ_IDENTITY) == (1.0, 0.0)
    assert q_conj((1.0, 2.0, 3.0, 4.0)) == (1.0, -2.0, -3.0, -4.0)
