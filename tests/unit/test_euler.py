"""Instants where a Z-Y-X Euler description is singular or jumps (for Fig. 4)."""

from __future__ import annotations

import numpy as np

from common import quaternion as quat
from common.config.scenario import load_scenario
from common.quaternion import zyx_euler_rows
from common.quaternion import zyx_euler_rows as zyx_euler
from fcu.control.dualquat import q_exp
from fcu.reference.trajectory import make_trajectory
from gcs.report.euler import zyx_events

from ..closed_loop.conftest import SCENARIOS


def test_zyx_euler_of_known_rotations():
    """Given rotations about single axes, then roll, pitch, yaw come out on their own."""
    q = np.array([q_exp((0.3, 0.0, 0.0)), q_exp((0.0, -0.4, 0.0)), q_exp((0.0, 0.0, 2.0))])
    np.testing.assert_allclose(zyx_euler(q), [[0.3, 0, 0], [0, -0.4, 0], [0, 0, 2.0]],
                               atol=1e-12)


def test_events_find_gimbal_lock_and_wraps():
    """Given a pitch sweep through +90 deg and a yaw sweep through 180 deg, then one singular
    and one jump event are found at the right instants."""
    t = np.linspace(0.0, 1.0, 1001)
    pitch = np.array([q_exp((0.0, a, 0.0)) for a in np.linspace(1.2, 1.9, 1001)])
    yaw = np.array([q_exp((0.0, 0.0, a)) for a in np.linspace(3.0, 3.3, 1001)])
    (ts, kind), = zyx_events(t, pitch)
    assert kind == "singular" and abs(ts - (np.pi / 2 - 1.2) / 0.7) < 0.01
    (ts, kind), = zyx_events(t, yaw)
    assert kind == "jump" and abs(ts - (np.pi - 3.0) / 0.3) < 0.002


def test_case1_reference_has_four_yaw_wraps_and_no_gimbal_lock():
    """Given the Case I attitude (rotation about the fixed axis [1, 2, 3]), then a Z-Y-X
    description never locks (|pitch| <= 0.92 rad) but wraps four times (cf. Fig. 4's marks)."""
    traj = make_trajectory(load_scenario(SCENARIOS / "case1_figure8.toml").trajectory)
    t = np.arange(0.0, 160.0, 0.01)
    q = np.array([traj.sample(x).q_enu_flu for x in t])
    assert np.max(np.abs(zyx_euler(q)[:, 1])) < 0.92
    events = zyx_events(t, q)
    assert [k for _, k in events] == ["jump"] * 4
    np.testing.assert_allclose([x for x, _ in events], [50.24, 73.55, 94.33, 122.85], atol=0.02)


def test_scalar_and_row_euler_angles_agree():
    """Given random attitudes, then common.quaternion's scalar Z-Y-X angles (and its yaw)
    equal its row form and the report's, and compose back to the attitude."""
    rng = np.random.default_rng(3)
    q = rng.normal(size=(200, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    rows = zyx_euler_rows(q)
    scalar = np.array([quat.zyx_euler(tuple(r)) for r in q.tolist()])
    np.testing.assert_allclose(scalar, rows, rtol=0.0, atol=1e-15)
    np.testing.assert_array_equal(rows, zyx_euler(q))
    np.testing.assert_array_equal(scalar[:, 2], [quat.zyx_yaw(tuple(r)) for r in q.tolist()])
    for r, (roll, pitch, yaw) in zip(q.tolist(), scalar.tolist(), strict=True):
        back = quat.q_mul(q_exp((0.0, 0.0, yaw)),
                          quat.q_mul(q_exp((0.0, pitch, 0.0)), q_exp((roll, 0.0, 0.0))))
        assert quat.q_angle(quat.q_mul(quat.q_conj(back), tuple(r))) < 1e-9
