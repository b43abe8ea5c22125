"""The ULog writer, proven with pyulog (the reference reader): layouts, information,
parameters, logged strings, a log cut anywhere (the writers killed or stopped by a full
disk in a process of their own: tests/sitl/test_ulog_writers.py)."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from common.logs import px4_topics as px4
from common.logs.ulog import Topic, ULogError, ULogWriter, open_ulog, read_topic, tail_record

POSE = Topic("pose", (("uint64_t", "timestamp"), ("double", "x"), ("float", "q", 4),
                      ("int8_t", "flag"), ("bool", "ok")))
RATE = Topic("rate", (("uint64_t", "timestamp"), ("double", "w")))


def test_records_info_params_and_strings_read_back_by_pyulog(tmp_path):
    path = tmp_path / "a.ulg"
    w = ULogWriter(path, [POSE, RATE], start_us=5,
                   info={"sys_name": "dqflight", "ver_hw": "SITL", "count": 7},
                   params={"MPC_XY_VEL_MAX": 12.5, "COM_ARM": 3})
    for i in range(100):
        w.add("pose", (1000 * i, i * 0.1, 1.0, 0.0, -0.5, 0.25, -3, i % 2 == 0))
        if i % 10 == 0:
            w.add("rate", (1000 * i, -i * 1e-9))
    w.log(2500, 4, "rotors saturated")
    w.param("MPC_XY_VEL_MAX", 3.0)
    w.close()
    u = open_ulog(path)
    assert not u.file_corruption
    assert u.start_timestamp == 5
    assert u.msg_info_dict["sys_name"] == "dqflight" and u.msg_info_dict["count"] == 7
    assert u.initial_parameters == {"MPC_XY_VEL_MAX": 12.5, "COM_ARM": 3}
    assert [(p[1], p[2]) for p in u.changed_parameters] == [("MPC_XY_VEL_MAX", 3.0)]
    (msg,) = u.logged_messages
    assert (msg.timestamp, msg.log_level_str(), msg.message) == (2500, "WARNING",
                                                               "rotors saturated")
    pose = u.get_dataset("pose")
    assert pose.data["x"].dtype == np.float64 and pose.data["q[2]"].dtype == np.float32
    assert np.array_equal(pose.data["timestamp"], 1000 * np.arange(100))
    assert np.array_equal(pose.data["x"], np.arange(100) * 0.1)  # float64 exactly
    assert np.all(pose.data["q[2]"] == -0.5) and np.all(pose.data["flag"] == -3)
    assert list(pose.data["ok"][:4]) == [1, 0, 1, 0]
    cols, rows = read_topic(path, "rate")
    assert cols == ("time_us", "w") and rows.shape == (10, 2)
    assert rows[3, 1] == -30 * 1e-9


def test_px4_layouts_are_valid_ulog_formats(tmp_path):
    """Every PX4 layout (the estimator's too) is written and read back field for field
    (names as PX4 has them)."""
    topics = [v for v in vars(px4).values() if isinstance(v, Topic)]
    assert len(topics) == 16
    topics += list(px4.ESTIMATOR_TOPICS)
    w = ULogWriter(tmp_path / "px4.ulg", topics)
    for t in topics:
        w.add(t.name, (1, *[0] * (t.width - 1)))
    w.close()
    u = open_ulog(tmp_path / "px4.ulg")
    assert sorted(d.name for d in u.data_list) == sorted(t.name for t in topics)
    lp = u.get_dataset("vehicle_local_position_groundtruth")
    assert {"x", "y", "z", "vx", "vy", "vz", "heading", "ref_lat"} <= set(lp.data)
    assert {"q[0]", "q[3]"} <= set(u.get_dataset("vehicle_attitude").data)
    assert {"control[11]"} <= set(u.get_dataset("actuator_motors").data)


def test_record_conversions_to_ned_frd():
    """A pose in ENU/FLU becomes PX4's NED position and FRD->NED attitude: the identity
    attitude in ENU/FLU (nose east) is heading +90 deg in NED."""
    rec = px4.local_position_record(10, 9, (1.0, 2.0, 3.0), (0.1, 0.2, 0.3),
                                    (1.0, 0.0, 0.0, 0.0), True, (0, 47.0, 8.0, 400.0))
    assert rec[6:9] == (2.0, 1.0, -3.0) and rec[9:12] == (0.2, 0.1, -0.3)
    assert rec[12] == pytest.approx(math.pi / 2)
    att = px4.attitude_record(10, 9, (1.0, 0.0, 0.0, 0.0))
    h = math.sqrt(0.5)
    assert att[2:6] == pytest.approx((h, 0.0, 0.0, h))  # yaw +90 deg about NED down
    assert px4.angular_velocity_record(1, 1, (0.1, 0.2, 0.3))[2:] == (0.1, -0.2, -0.3)



def test_a_log_cut_anywhere_reads_to_its_last_complete_record(tmp_path):
    """A file cut at every byte of its last records (a kill between two writes of one
    flush, a full disk) reads back to the last complete record."""
    path = tmp_path / "full.ulg"
    w = ULogWriter(path, [RATE])
    for i in range(20):
        w.add("rate", (i, float(i)))
    w.close()
    raw = path.read_bytes()
    record = 3 + 2 + 16
    for cut in range(len(raw) - 3 * record, len(raw) + 1):
        (tmp_path / "cut.ulg").write_bytes(raw[:cut])
        _, rows = read_topic(tmp_path / "cut.ulg", "rate")
        complete = 20 - math.ceil((len(raw) - cut) / record)
        assert len(rows) == complete and np.array_equal(rows[:, 1], np.arange(complete))


def test_bad_files_and_topics_are_clear_errors(tmp_path):
    (tmp_path / "text.ulg").write_text("not a log")
    with pytest.raises(ULogError, match="not a ULog"):
        read_topic(tmp_path / "text.ulg", "rate")
    with pytest.raises(ULogError, match="No such file"):
        read_topic(tmp_path / "missing.ulg", "rate")
    w = ULogWriter(tmp_path / "a.ulg", [RATE])
    w.close()
    cols, rows = read_topic(tmp_path / "a.ulg", "rate")  # declared, never written
    assert cols == ("time_us", "w") and rows.shape == (0, 2)
    with pytest.raises(ULogError, match="no topic pose"):
        read_topic(tmp_path / "a.ulg", "pose")
    with pytest.raises(ValueError, match="timestamp"):
        Topic("bad", (("double", "x"),))
    with pytest.raises(ValueError, match="unknown type"):
        Topic("bad", (("uint64_t", "timestamp"), ("float32", "x")))


# ------------------------------------------------------------------------ record builders

def _rot(q_wxyz):
    w, x, y, z = q_wxyz
    return Rotation.from_quat([x, y, z, w])


NED_FROM_ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
FRD_FROM_FLU = np.diag([1.0, -1.0, -1.0])


def _random_motion(rng):
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    return (tuple(rng.normal(size=3) * 5), tuple(rng.normal(size=3)), tuple(rng.normal(size=3)),
            tuple(q), tuple(rng.normal(size=3)))


def test_setpoint_records_against_an_independent_rotation_library():
    """Setpoints in NED/FRD from ENU/FLU values, checked with scipy's rotations: position,
    velocity, acceleration, the attitude (FRD -> NED), yaw, yaw rate about NED down and the
    body rate in FRD."""
    rng = np.random.default_rng(3)
    for _ in range(200):
        p, v, a, q, w = _random_motion(rng)
        r_enu_flu = _rot(q)
        r_ned_frd = Rotation.from_matrix(NED_FROM_ENU @ r_enu_flu.as_matrix() @ FRD_FROM_FLU)
        yaw = r_ned_frd.as_euler("ZYX")[0]
        yawspeed = (NED_FROM_ENU @ r_enu_flu.apply(w))[2]
        ts = px4.trajectory_setpoint_record(7, p, v, a, q, w)
        assert ts[1:4] == pytest.approx(NED_FROM_ENU @ p)
        assert ts[4:7] == pytest.approx(NED_FROM_ENU @ v)
        assert ts[7:10] == pytest.approx(NED_FROM_ENU @ a)
        assert all(math.isnan(j) for j in ts[10:13])
        assert math.cos(ts[13] - yaw) == pytest.approx(1.0) and ts[14] == pytest.approx(yawspeed)
        lps = px4.local_position_setpoint_record(7, p, v, a, q, w)
        assert lps[1:10] == pytest.approx(ts[1:10]) and lps[10:] == pytest.approx(ts[13:])
        att = px4.attitude_setpoint_record(7, q, w)
        x, y, z, s = r_ned_frd.as_quat()
        assert abs(abs(np.dot(att[2:6], (s, x, y, z))) - 1.0) < 1e-12
        assert att[1] == pytest.approx(yawspeed)
        rates = px4.rates_setpoint_record(7, w)
        assert rates[1:4] == pytest.approx(FRD_FROM_FLU @ w)


def test_actuator_records_follow_px4_ranges():
    """Motors: speed / limit in [0, 1], NaN when disarmed and unused; servos: the tilt wrapped
    into [-pi, pi) over pi; saturation: upper at the limit, lower when stopped while armed."""
    speeds = (0.0, 850.0, 1700.0, 1800.0, 10.0, 1699.0)
    m = px4.actuator_motors_record(5, 4, speeds, 1700.0, True)
    assert m[3:9] == pytest.approx((0.0, 0.5, 1.0, 1800 / 1700, 10 / 1700, 1699 / 1700))
    assert all(math.isnan(c) for c in m[9:])
    assert all(math.isnan(c) for c in px4.actuator_motors_record(5, 4, speeds, 1700.0,
                                                                  False)[3:])
    tilts = (0.0, math.pi / 2, -math.pi / 2, 3 * math.pi / 2, -7.0, 2 * math.pi + 0.1)
    s = px4.actuator_servos_record(5, 4, tilts)
    assert s[2:8] == pytest.approx((0.0, 0.5, -0.5, -0.5, (-7.0 + 2 * math.pi) / math.pi,
                                    0.1 / math.pi))
    assert all(math.isnan(c) for c in s[8:])
    c = px4.control_allocator_status_record(5, speeds, 1700.0, True, True)
    assert c[1:3] == (False, False)
    assert c[3:9] == (px4.ACTUATOR_SATURATION_LOWER, 0, px4.ACTUATOR_SATURATION_UPPER,
                      px4.ACTUATOR_SATURATION_UPPER, 0, 0)
    assert px4.control_allocator_status_record(5, speeds, 1700.0, False, False)[1:4] == (
        True, True, 0)


# ------------------------------------------------------------------------ tail_record

def test_tail_record_finds_the_last_complete_record_of_a_rare_topic(tmp_path):
    """A topic written once behind more than the first window of other records, and a file
    cut at every byte of its end: tail_record agrees with pyulog."""
    path = tmp_path / "a.ulg"
    w = ULogWriter(path, [POSE, RATE])
    w.add("rate", (1, 1.0))
    for i in range(5000):  # 5000 x 36 bytes: beyond the first 64 KiB window
        w.add("pose", (i, float(i), 1.0, 0.0, 0.0, 0.0, 1, True))
    w.close()
    assert tail_record(path, "rate") == (("time_us", "w"), (1.0, 1.0))
    raw = path.read_bytes()
    for cut in range(len(raw) - 80, len(raw) + 1):
        (tmp_path / "cut.ulg").write_bytes(raw[:cut])
        _, rows = read_topic(tmp_path / "cut.ulg", "pose")
        tail = tail_record(tmp_path / "cut.ulg", "pose")
        assert tail is not None and tail[1][:2] == tuple(rows[-1, :2])


def test_tail_record_is_not_fooled_by_a_record_inside_another_payload(tmp_path):
    """A float64 payload that holds the bytes of a `rate` message is not a `rate` record."""
    import struct

    big = Topic("big", (("uint64_t", "timestamp"), ("double", "v", 8)))
    path = tmp_path / "fake.ulg"
    w = ULogWriter(path, [RATE, big])
    w.add("rate", (5, 2.0))
    fake = struct.pack("<HBH", 18, ord("D"), 0) + struct.pack("<Qd", 999_999, -42.0)
    payload = np.frombuffer(fake + bytes(64 - len(fake)), dtype="<f8")
    w.add("big", (6, *payload))
    w.close()
    _, rows = read_topic(path, "rate")
    assert rows.tolist() == [[5.0, 2.0]]
    assert tail_record(path, "rate") == (("time_us", "w"), (5.0, 2.0))


# ------------------------------------------------------------------------ a failing disk



def test_a_close_beside_returns_before_its_fsync_and_the_file_ends_complete(tmp_path,
                                                                           monkeypatch):
    """Given a log closed `beside` (log rotation in the control loop) while the disk's sync
    is held, then close returns with every record written and the sync still pending; once
    the sync is let go, its thread syncs and ends."""
    import threading

    import common.logs.ulog as ulog
    held, synced = threading.Event(), []
    real_fsync = os.fsync

    def slow_fsync(fd: int) -> None:
        assert held.wait(10.0)
        real_fsync(fd)
        synced.append(fd)

    monkeypatch.setattr(ulog.os, "fsync", slow_fsync)
    path = tmp_path / "a.ulg"
    w = ULogWriter(path, [POSE])
    for i in range(50):
        w.add("pose", (1000 * i, 0.0, 1.0, 0.0, 0.0, 0.0, 0, True))
    w.close(beside=True)
    assert not synced and len(read_topic(path, "pose")[1]) == 50  # written, not yet synced
    (closer,) = [t for t in threading.enumerate() if t.name == "ulog-close"]
    held.set()
    closer.join(10.0)
    assert len(synced) == 1 and not closer.is_alive()
