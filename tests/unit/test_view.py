"""`gcs view`'s pure parts: wire poses in ENU/FLU, arm transforms against the rotor geometry,
bounded paths, the frame tree, the state message, replay sampling and the publishing tick."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from common.config.scenario import load_vehicle
from common.geometry import rotor_frames
from common.quaternion import q_angle, q_conj, q_exp, q_mul, q_rotate
from gcs.view.replay import ReplayLog
from gcs.view.sample import (
    PathBuffer,
    Pose,
    Sample,
    arm_mounts,
    arm_transform,
    pose_from_ned,
    state_message,
    transforms,
)
from gcs.view.settings import BASE_HZ, DEFAULT_VEHICLE, RATES_HZ, due_topics, replay_ticks

VEHICLE = DEFAULT_VEHICLE
H = math.sqrt(0.5)


def _close(a, b, tol=1e-12) -> bool:
    return all(abs(x - y) <= tol for x, y in zip(a, b, strict=True))


def _same_rotation(q1, q2, tol=1e-12) -> bool:
    return q_angle(q_mul(q_conj(q1), q2)) <= tol


def test_ned_pose_to_enu():
    """NED (north 1, east 2, down -3) is ENU (east 2, north 1, up 3); yaw +90 deg in NED
    (body x east) is the ENU/FLU identity; a roll of r about FRD x is a roll of r about FLU x
    (x forward in both), seen with body x east."""
    pose = pose_from_ned((1.0, 2.0, -3.0), (H, 0.0, 0.0, H))
    assert _close(pose.p_enu_m, (2.0, 1.0, 3.0))
    assert _same_rotation(pose.q_enu_flu, (1.0, 0.0, 0.0, 0.0))

    r = 0.3
    q_ned_frd = q_mul((H, 0.0, 0.0, H), q_exp((r, 0.0, 0.0)))  # yaw 90 then roll r
    q = pose_from_ned((0.0, 0.0, 0.0), q_ned_frd).q_enu_flu
    assert _same_rotation(q, q_exp((r, 0.0, 0.0)), 1e-12)
    # body z (up in FLU) after a roll r about east: (0, -sin r, cos r) in ENU
    assert _close(q_rotate(q, (0.0, 0.0, 1.0)), (0.0, -math.sin(r), math.cos(r)))


@pytest.mark.parametrize("tilt", [0.0, math.pi / 2, -0.7, 2.5, 7.0])
def test_arm_transform_turns_the_rotor_axis_as_the_geometry_says(tilt):
    """Arm i's frame sits at r_i, its x axis is the arm a_i and its z axis the thrust
    direction n_i = cos(alpha) e_v + sin(alpha) e_l of common.geometry (tilt pi/2: e_l)."""
    vehicle = load_vehicle(VEHICLE)
    for mount, fr in zip(arm_mounts(vehicle), rotor_frames(vehicle), strict=True):
        translation, q = arm_transform(mount, tilt)
        assert _close(translation, fr.r_flu_m)
        assert _close(q_rotate(q, (1.0, 0.0, 0.0)), fr.arm_flu)
        n = tuple(math.cos(tilt) * v + math.sin(tilt) * l
                  for v, l in zip(fr.e_v_flu, fr.e_l_flu, strict=True))
        assert _close(q_rotate(q, (0.0, 0.0, 1.0)), n, 1e-12)
    mount = arm_mounts(vehicle)[1]
    _, q = arm_transform(mount, math.pi / 2)
    assert _close(q_rotate(q, (0.0, 0.0, 1.0)), rotor_frames(vehicle)[1].e_l_flu, 1e-12)


def test_path_is_bounded_in_time_and_spacing():
    """One point per spacing, none older than the window, cleared when time goes back."""
    path = PathBuffer(window_us=1_000_000, spacing_us=100_000)
    for k in range(0, 5_000_000, 20_000):  # 50 Hz for 5 s
        path.add(k, (k * 1e-6, 0.0, 0.0))
    times = path.times_us()
    assert len(path) == 11
    assert times[-1] == 4_900_000 and times[-1] - times[0] <= 1_000_000
    assert all(b - a >= 100_000 for a, b in itertools.pairwise(times))
    assert path.points()[-1] == pytest.approx((4.9, 0.0, 0.0))
    path.add(1_000, (9.0, 9.0, 9.0))  # a new flight
    assert path.points() == [(9.0, 9.0, 9.0)]
    long = PathBuffer()  # default: 60 s at 10 points/s
    for k in range(0, 300_000_000, 50_000):
        long.add(k, (0.0, 0.0, 0.0))
    assert len(long) == 601


def test_frame_tree_of_a_sample():
    """world->base_link, world->desired, base_link->arm_i (tilted, stamped with the
    actuators' time), arm_i->rotor_i; untilted arms before any actuator output."""
    vehicle = load_vehicle(VEHICLE)
    mounts = arm_mounts(vehicle)
    assert transforms(Sample(), mounts) == []
    tilts = (0.1, -0.2, 0.3, -0.4, 0.5, -0.6)
    s = Sample(pose=Pose((1.0, 2.0, 3.0), (1.0, 0.0, 0.0, 0.0)), pose_time_us=5_000,
               desired=Pose((0.0, 0.0, 2.0), (1.0, 0.0, 0.0, 0.0)), desired_time_us=4_000,
               rotor_speeds_rad_s=(500.0,) * 6, tilts_rad=tilts, actuator_time_us=3_000)
    edges = transforms(s, mounts)
    assert [(e.parent, e.child) for e in edges[:2]] == [("world", "base_link"),
                                                         ("world", "desired")]
    assert edges[0].time_us == 5_000 and edges[0].translation == (1.0, 2.0, 3.0)
    arms = {e.child: e for e in edges if e.parent == "base_link"}
    rotors = {e.child: e for e in edges if e.parent.startswith("arm_")}
    assert sorted(arms) == [f"arm_{i}" for i in range(6)]
    assert sorted(rotors) == [f"rotor_{i}" for i in range(6)]
    for i, fr in enumerate(rotor_frames(vehicle)):
        e = arms[f"arm_{i}"]
        assert e.time_us == 3_000
        n = tuple(math.cos(tilts[i]) * v + math.sin(tilts[i]) * l
                  for v, l in zip(fr.e_v_flu, fr.e_l_flu, strict=True))
        assert _close(q_rotate(e.rotation, (0.0, 0.0, 1.0)), n, 1e-12)
    untilted = transforms(Sample(pose=s.pose, pose_time_us=7_000), mounts)
    arm0 = next(e for e in untilted if e.child == "arm_0")
    assert arm0.time_us == 7_000
    assert _close(q_rotate(arm0.rotation, (0.0, 0.0, 1.0)), rotor_frames(vehicle)[0].e_v_flu)


def test_state_message_is_json_safe():
    s = Sample(pose=Pose((1.0, 2.0, 3.0), (1.0, 0.0, 0.0, 0.0)), pose_time_us=2_500_000,
               rotor_speeds_rad_s=(1.0, math.nan, 3.0, 4.0, 5.0, 6.0),
               tilts_rad=(0.0,) * 6, actuator_time_us=2_000_000, mode="MISSION", armed=True)
    m = state_message(s, "live")
    assert m["time_s"] == 2.5 and m["mode"] == "MISSION" and m["armed"] is True
    assert m["rotor_speeds_rad_s"] == [1.0, None, 3.0, 4.0, 5.0, 6.0]
    assert m["position_enu_m"] == [1.0, 2.0, 3.0] and m["desired_position_enu_m"] is None


def test_replay_samples_the_last_rows_at_or_before():
    truth_cols = ("time_us", "px", "py", "pz", "qw", "qx", "qy", "qz",
                  *(f"rotor{i}" for i in range(6)), *(f"tilt{i}" for i in range(6)))
    truth = np.array([[t, t, 0, 0, 1, 0, 0, 0, *([t] * 6), *([t * 1e-6] * 6)]
                      for t in (0, 2000, 4000)], dtype=float)
    ob_cols = ("time_us", "pdx", "pdy", "pdz", "qdw", "qdx", "qdy", "qdz", "armed")
    onboard = np.array([[0, 0, 0, 1, 1, 0, 0, 0, 0], [3000, 0, 0, 2, 1, 0, 0, 0, 1]], float)
    log = ReplayLog.from_rows(truth_cols, truth, ob_cols, onboard)
    assert log.span_us == (0, 4000)
    s = log.sample_at(3999)
    assert s.pose_time_us == 2000 and s.pose is not None and s.pose.p_enu_m == (2000.0, 0, 0)
    assert s.tilts_rad == (0.002,) * 6 and s.actuator_time_us == 2000
    assert s.desired is not None and s.desired.p_enu_m == (0.0, 0.0, 2.0) and s.armed is True
    assert s.time_us == 3000
    assert log.sample_at(-1).pose is None
    assert list(replay_ticks(0, 100_000)) == [0, 50_000, 100_000]


def test_publishing_tick_gives_each_channel_its_rate():
    counts = dict.fromkeys(RATES_HZ, 0)
    for tick in range(BASE_HZ * 10):
        for topic in due_topics(tick):
            counts[topic] += 1
    assert counts == {topic: 10 * hz for topic, hz in RATES_HZ.items()}
