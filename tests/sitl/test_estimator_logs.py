"""The estimator in onboard.ulg (PX4's sensor_combined, vehicle_visual_odometry,
estimator_states, estimator_innovations, estimator_innovation_test_ratios,
estimator_status), `gcs replay` on it, and the report's estimator figures, on in-process
runs (the run through processes is tests/sitl/test_replay.py)."""

from __future__ import annotations

import json
import math
import random
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from common.frames import q_ned_frd_to_enu_flu
from common.logs import px4_topics as px4
from common.logs.ulog import open_ulog
from gcs.run import replay as rp

ROOT = Path(__file__).resolve().parents[2]
CASE1 = ROOT / "config" / "scenarios" / "case1_figure8.toml"
DURATION_S = 4.0

# topic -> (rate in Hz with mocap-indoor, fields that must be there)
ESTIMATOR_TOPICS = {
    "sensor_combined": (1000, ("gyro_rad[0]", "gyro_rad[2]", "accelerometer_m_s2[1]",
                               "gyro_integral_dt", "accelerometer_integral_dt",
                               "accelerometer_timestamp_relative")),
    "vehicle_visual_odometry": (200, ("timestamp_sample", "pose_frame", "position[0]",
                                      "position[2]", "q[0]", "q[3]", "velocity[0]",
                                      "position_variance[0]", "orientation_variance[2]",
                                      "quality")),
    "estimator_states": (50, ("timestamp_sample", "states[0]", "states[9]", "states[15]",
                              "n_states", "covariances[0]", "covariances[14]")),
    "estimator_innovations": (50, ("ev_hpos[0]", "ev_hpos[1]", "ev_vpos", "heading")),
    "estimator_innovation_test_ratios": (50, ("ev_hpos[0]", "ev_vpos", "heading")),
    "estimator_status": (50, ("pos_horiz_accuracy", "pos_vert_accuracy", "pos_test_ratio",
                              "hgt_test_ratio", "mag_test_ratio", "control_mode_flags",
                              "filter_fault_flags", "gps_check_fail_flags",
                              "solution_status_flags")),
}


def _gcs(*args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "gcs.cli", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout, check=False)


def _run(out: Path, *extra: str) -> Path:
    proc = _gcs("run", str(CASE1), "--in-process", "--duration", f"{DURATION_S:g}",
                "--out", str(out), *extra)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return out


@pytest.fixture(scope="module")
def est_run(tmp_path_factory) -> Path:
    return _run(tmp_path_factory.mktemp("est") / "run", "--sensors", "mocap-indoor")


@pytest.fixture(scope="module")
def truth_run(tmp_path_factory) -> Path:
    return _run(tmp_path_factory.mktemp("truth") / "run")


def _rate_hz(ts: np.ndarray) -> float:
    return (len(ts) - 1) / ((ts[-1] - ts[0]) * 1e-6)


def test_the_six_estimator_topics_with_their_fields_at_their_rates(est_run):
    u = open_ulog(est_run / "onboard.ulg")
    assert not u.file_corruption
    for name, (rate, fields) in ESTIMATOR_TOPICS.items():
        d = u.get_dataset(name)
        assert set(fields) <= set(d.data), (name, set(fields) - set(d.data))
        ts = d.data["timestamp"].astype(np.int64)
        assert np.all(np.diff(ts) > 0), name
        assert _rate_hz(ts) == pytest.approx(rate, rel=0.01), name
        floats = [f for f in fields if f[-1] == "]" and "flags" not in f]
        assert all(d.data[f].dtype == np.float32 for f in floats), name
    imu = u.get_dataset("sensor_combined").data
    assert np.all(imu["gyro_integral_dt"][1:] == 1000)
    odo = u.get_dataset("vehicle_visual_odometry").data
    assert np.all(odo["pose_frame"] == px4.POSE_FRAME_NED)
    assert np.all(np.isnan(odo["velocity[0]"]))
    # received after its capture (mocap-indoor: 5 ms latency), stamped on an IMU sample
    lag = odo["timestamp"].astype(np.int64) - odo["timestamp_sample"].astype(np.int64)
    assert np.all(lag == 5000)
    assert set(odo["timestamp"].astype(np.int64).tolist()) <= set(
        imu["timestamp"].astype(np.int64).tolist())
    st = u.get_dataset("estimator_states").data
    assert np.all(st["n_states"] == px4.N_STATES)
    q = np.column_stack([st[f"states[{i}]"] for i in range(4)]).astype(float)
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-6)
    status = u.get_dataset("estimator_status").data
    last = int(status["control_mode_flags"][-1])
    assert last & (1 << px4.CS_TILT_ALIGN) and last & (1 << px4.CS_EV_POS)
    assert last & (1 << px4.CS_IN_AIR)
    assert np.all(status["filter_fault_flags"] == 0)
    assert 0.0 < float(status["pos_horiz_accuracy"][-1]) < 0.01
    ratios = u.get_dataset("estimator_innovation_test_ratios").data
    assert 0.0 < float(np.max(ratios["ev_vpos"])) < 1.0  # every pose fused


def test_the_estimate_logged_is_the_state_the_controller_flew_on(est_run):
    """estimator_states' position at each PX4-rate step is vehicle_local_position's."""
    u = open_ulog(est_run / "onboard.ulg")
    st = u.get_dataset("estimator_states").data
    lp = u.get_dataset("vehicle_local_position").data
    common, i, j = np.intersect1d(st["timestamp"], lp["timestamp"], return_indices=True)
    assert len(common) > 100
    assert np.array_equal(st["states[7]"][i], lp["x"][j])
    assert np.array_equal(st["states[9]"][i], lp["z"][j])


def test_a_truth_run_has_no_estimator_topics(truth_run):
    u = open_ulog(truth_run / "onboard.ulg")
    names = {d.name for d in u.data_list}
    assert not names & set(ESTIMATOR_TOPICS)
    assert "dq_onboard" in names and "vehicle_local_position" in names
    assert "dq_gravity_m_s2" not in u.msg_info_dict


def test_replay_reproduces_the_logged_estimate_bit_for_bit(est_run, tmp_path):
    r = rp.replay(est_run / "onboard.ulg")
    # every IMU sample from 0 to the end (alignment, then 4 s of flight), a pose per 5 ms
    end_us = round(json.loads((est_run / "metrics.json").read_text())["alignment_s"] * 1e6) \
        + 4_000_000
    assert len(r.time_us) == 2001 and r.imu_samples == end_us // 1000 + 1
    assert r.poses == (end_us - 5000) // 5000 + 1  # captures 0 .. end - latency
    assert r.bit_identical and r.agree
    proc = _gcs("replay", str(est_run / "onboard.ulg"), "--out", str(tmp_path / "r.json"))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "bit-identical" in proc.stdout
    doc = json.loads((tmp_path / "r.json").read_text())
    assert doc["columns"] == ["time_us", *rp.STATE_COLUMNS] and len(doc["rows"]) == 2001


def test_replay_notices_a_missing_pose_or_a_changed_parameter(est_run, monkeypatch):
    log = est_run / "onboard.ulg"
    r = rp.replay(log, rp.parse_params(["EKF_EVP_NOISE=0.01"]))
    assert not r.agree
    text, status = rp.report(r, {"EKF_EVP_NOISE": 0.01})
    assert status == 1 and "position difference" in text
    inputs = rp._inputs

    def one_pose_less(ulog):
        items, n_imu, n_pose = inputs(ulog)
        k = next(k for k, it in enumerate(items) if it[1] == 0 and it[0] > 2_000_000)
        return [*items[:k], *items[k + 1:]], n_imu, n_pose - 1

    monkeypatch.setattr(rp, "_inputs", one_pose_less)
    assert not rp.replay(log).agree

    def imu_after_pose(ulog):  # the other order at equal timestamps
        items, n_imu, n_pose = inputs(ulog)
        return sorted(items, key=lambda it: (it[0], -it[1], it[2])), n_imu, n_pose

    monkeypatch.setattr(rp, "_inputs", imu_after_pose)
    assert not rp.replay(log).agree


def test_replay_exits_1_with_a_parameter_and_2_for_bad_input(est_run, truth_run, tmp_path):
    log = str(est_run / "onboard.ulg")
    proc = _gcs("replay", log, "--param", "EKF_EVP_NOISE=0.01", "--out",
                str(tmp_path / "r.csv"))
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "differ" in proc.stdout
    lines = (tmp_path / "r.csv").read_text().splitlines()
    assert lines[0].split(",") == ["time_us", *rp.STATE_COLUMNS] and len(lines) == 2002
    for args in ((str(est_run / "metrics.json"),), (str(truth_run / "onboard.ulg"),),
                 (log, "--param", "EKF_NOPE=1"), (log, "--param", "EKF_EVP_NOISE=-1"),
                 (str(tmp_path / "missing.ulg"),)):
        proc = _gcs("replay", *args)
        assert proc.returncode == 2, (args, proc.stdout + proc.stderr)
        assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr


def test_report_draws_the_estimator_figures_only_with_the_estimator(est_run, truth_run):
    for run, drawn in ((est_run, True), (truth_run, False)):
        proc = _gcs("report", str(run))
        assert proc.returncode == 0, proc.stdout + proc.stderr
        md = (run / "report.md").read_text()
        for name in ("estimation.png", "innovations.png"):
            png = run / "figures" / name
            assert png.exists() == drawn
            assert (f"figures/{name}" in md) == drawn
            if drawn:
                assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20000
        assert ("## Estimation error" in md) == drawn


def test_estimator_layouts_declare_the_fields_px4_names():
    """The layouts (written and read back with every PX4 layout in test_ulog) declare the
    fields this module's readers look up."""
    topics = {t.name: t for t in px4.ESTIMATOR_TOPICS}
    assert list(topics) == list(ESTIMATOR_TOPICS)
    for name, (_, fields) in ESTIMATOR_TOPICS.items():
        declared = {f[1] if len(f) == 2 else f"{f[1]}[{i}]"
                    for f in topics[name].fields for i in range(f[2] if len(f) == 3 else 1)}
        assert set(fields) <= declared, name


def _f32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", x))[0]


def test_the_logged_attitude_converts_back_to_what_the_fcu_received():
    """q_ned_frd_to_enu_flu(wire_q_ned_frd(q)) == q bit for bit for q from a float32 wire
    quaternion, also with zero and small components (where the plain inverse misses)."""
    rng = random.Random(3)
    misses = plain_misses = 0
    n = 20000
    for i in range(n):
        c = [rng.gauss(0.0, 1.0) for _ in range(4)]
        if i % 4 == 0:
            c[rng.randrange(4)] = 0.0
        elif i % 4 == 1:
            c[rng.randrange(4)] *= 1e-7
        norm = math.sqrt(sum(x * x for x in c))
        wire = tuple(_f32(x / norm) for x in c)
        q_enu = q_ned_frd_to_enu_flu((wire[0], wire[1], wire[2], wire[3]))
        logged = tuple(_f32(x) for x in px4.wire_q_ned_frd(q_enu))
        back = q_ned_frd_to_enu_flu((logged[0], logged[1], logged[2], logged[3]))
        misses += struct.pack("<4d", *back) != struct.pack("<4d", *q_enu)
        plain = tuple(_f32(x) for x in px4.q_enu_flu_to_ned_frd(q_enu))
        plain_misses += struct.pack("<4d", *q_ned_frd_to_enu_flu(
            (plain[0], plain[1], plain[2], plain[3]))) != struct.pack("<4d", *q_enu)
    assert plain_misses > 0  # the search is needed
    assert misses == 0
