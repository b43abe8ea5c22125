"""The one ENU/FLU <-> NED/FRD conversion: round trips and the identities of
docs/design.md#conventions."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from common.frames import (
    enu_to_ned,
    flu_to_frd,
    frd_to_flu,
    ned_to_enu,
    q_enu_flu_to_ned_frd,
    q_ned_frd_to_enu_flu,
)
from common.geodetic import ned_to_geodetic
from fcu.control.dualquat import cross, q_exp, q_mul, q_rotate

finite = st.floats(-100.0, 100.0, allow_nan=False)
vec = st.tuples(finite, finite, finite)
rotvec = st.tuples(*(st.floats(-3.0, 3.0, allow_nan=False),) * 3)


def _close(a, b, tol=1e-12):
    return np.allclose(a, b, atol=tol, rtol=0)


def test_axes_map_as_the_specification_says():
    """x_ned = y_enu, y_ned = x_enu, z_ned = -z_enu; FLU -> FRD flips y and z."""
    assert enu_to_ned((1.0, 2.0, 3.0)) == (2.0, 1.0, -3.0)
    assert flu_to_frd((1.0, 2.0, 3.0)) == (1.0, -2.0, -3.0)


def test_identity_attitude_is_yaw_90_degrees_in_ned():
    """Body x east (identity in ENU/FLU) is yaw = +90 deg about NED down."""
    q = q_enu_flu_to_ned_frd((1.0, 0.0, 0.0, 0.0))
    assert _close(q, (math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)))


@settings(max_examples=200, deadline=None)
@given(vec)
def test_world_and_body_vectors_round_trip(v):
    assert ned_to_enu(enu_to_ned(v)) == v
    assert frd_to_flu(flu_to_frd(v)) == v


@settings(max_examples=200, deadline=None)
@given(rotvec, vec)
def test_quaternion_conversion_agrees_with_vector_conversion(r, v):
    """R_ned_frd (v in FRD) equals the ENU->NED image of R_enu_flu (v in FLU)."""
    q = q_exp(r)
    q_ned = q_enu_flu_to_ned_frd(q)
    assert q_ned[0] >= 0.0
    assert _close(q_rotate(q_ned, flu_to_frd(v)), enu_to_ned(q_rotate(q, v)), 1e-9)
    back = q_ned_frd_to_enu_flu(q_ned)
    assert _close(back, q) or _close(back, tuple(-c for c in q))


@settings(max_examples=100, deadline=None)
@given(rotvec, vec, vec)
def test_body_rates_and_wrench_transform_as_body_vectors(r, w, f):
    """Rates, forces and torques are body vectors: cross products survive the flip."""
    assert _close(flu_to_frd(cross(w, f)), cross(flu_to_frd(w), flu_to_frd(f)), 1e-9)
    # and a rate in the body frame rotates to the same world rate in both conventions
    q = q_exp(r)
    assert _close(q_rotate(q_enu_flu_to_ned_frd(q), flu_to_frd(w)),
                  enu_to_ned(q_rotate(q, w)), 1e-9)


def test_composition_of_attitudes_is_preserved():
    """Converting a product equals the product in the wire frames up to the fixed maps."""
    a, b = q_exp((0.3, -0.2, 1.0)), q_exp((-1.0, 0.5, 0.2))
    lhs = q_enu_flu_to_ned_frd(q_mul(a, b))
    rhs = q_mul(q_enu_flu_to_ned_frd(a), q_mul((0.0, 1.0, 0.0, 0.0),  # FRD->FLU, pi about x
                                              q_mul(b, (0.0, 1.0, 0.0, 0.0))))
    assert _close(lhs, rhs, 1e-12) or _close(lhs, tuple(-c for c in rhs), 1e-12)


def test_geodetic_home_mapping():
    """One metre north is 1/R rad of latitude; altitude is home altitude minus NED z."""
    lat, lon, alt = ned_to_geodetic((1.0, 0.0, -5.0), 47.0, 8.0, 400.0)
    assert math.isclose(lat - 47.0, math.degrees(1.0 / 6_378_137.0), rel_tol=1e-9)
    assert lon == 8.0 and alt == 405.0


def test_the_written_out_conversion_is_the_two_products_to_the_bit():
    """q_enu_flu_to_ned_frd against q_ned_enu q q_flu_frd by the compiled `q_mul`, sign
    flipped to w >= 0: the same bits for unit, arbitrary, signed-zero and non-finite
    components."""
    from common.quaternion import q_mul

    h = math.sqrt(0.5)
    rng = np.random.default_rng(4)
    special = [0.0, -0.0, 1.0, -1.0, h, math.inf, -math.inf, math.nan, 1e-300, 3e300]
    cases = [tuple(float(c) for c in rng.normal(0.0, 1.0, 4)) for _ in range(2000)]
    cases += [tuple(float(c) for c in rng.choice(special, 4)) for _ in range(2000)]
    cases += [(1.0, 0.0, 0.0, 0.0), (-0.0, 0.0, -0.0, 1.0), (0.0, -0.0, 0.0, -0.0)]
    # a component of q_ned_enu q cancelling to zero (w = -z, w = z, x = -y, x = y): the
    # short form's fall-back decides its sign
    for a, b in rng.normal(0.0, 1.0, (500, 2)).tolist():
        cases += [(a, b, -b, -a), (a, b, b, a), (a, b, -b, a), (-a, b, b, -a)]
    # finite components whose products with the fixed rotations overflow (the sum of q's
    # components finite, its products not)
    cases += [(-1.7e308, 1.7e308, 1.6e308, -1.6e308), (1.7e308, -1.6e308, -1.7e308, 1.6e308)]
    for q in cases:
        r = q_mul(q_mul((0.0, h, h, 0.0), (q[0], q[1], q[2], q[3])), (0.0, 1.0, 0.0, 0.0))
        want = r if r[0] >= 0.0 else (-r[0], -r[1], -r[2], -r[3])
        got = q_enu_flu_to_ned_frd((q[0], q[1], q[2], q[3]))
        assert np.array(got).tobytes() == np.array(want).tobytes(), q
