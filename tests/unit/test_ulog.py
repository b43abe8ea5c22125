"""The ULog writer, proven with pyulog (the reference reader): layouts, information,
parameters, logged strings, and records that survive SIGKILL of their writer."""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from common import px4_topics as px4
from common.ulog import Topic, ULogError, ULogWriter, open_ulog, read_topic, tail_record

POSE = Topic("pose", (("uint64_t", "timestamp"), ("double", "x"), ("float", "q", 4),
                      ("int8_t", "flag"), ("bool", "ok")))
RATE = Topic("rate", (("uint64_t", "timestamp"), ("double", "w")))

WRITER = """
import sys
from common.ulog import Topic, ULogWriter
t = Topic("row", (("uint64_t", "timestamp"), ("double", "a"), ("double", "b")))
w = ULogWriter(sys.argv[1], [t])
i = 0
while True:
    w.add("row", (i, 2.0 * i, -i))
    i += 1
    if i % 3 == 0:
        w.flush()  # the processes flush once per control period
    if i % 999 == 0:
        print(i, flush=True)
"""


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
    """Every PX4 layout is written and read back field for field (names as PX4 has them)."""
    topics = [v for v in vars(px4).values() if isinstance(v, Topic)]
    assert len(topics) == 16
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


def test_records_survive_sigkill_of_the_writer(tmp_path):
    """Given a writer killed with SIGKILL mid-stream, then pyulog reads every record it had
    flushed, in order, without a torn record, and `tail_record` finds the same last one."""
    path = tmp_path / "killed.ulg"
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(path)], stdout=subprocess.PIPE,
                            text=True, cwd=os.getcwd())
    try:
        written = 0
        deadline = time.monotonic() + 30
        while written < 30000 and time.monotonic() < deadline:
            written = int(proc.stdout.readline())
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    u = open_ulog(path)
    assert not u.file_corruption
    rows = u.get_dataset("row").data
    n = len(rows["timestamp"])
    assert n >= written
    assert np.array_equal(rows["timestamp"], np.arange(n))
    assert np.array_equal(rows["a"], 2.0 * np.arange(n))
    cols, last = tail_record(path, "row")
    assert cols == ("time_us", "a", "b") and last == (n - 1, 2.0 * (n - 1), -(n - 1.0))


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
