"""The run folder's ULogs as a PX4 user opens them: pyulog reads truth.ulg and onboard.ulg of
runs through processes and in-process, with PX4's topics, fields, frames and rates; the
metrics computed from them are the run's (and the figures from before the logs became
ULog); after SIGKILL of `sitl` or `fcu` every complete record is readable."""

from __future__ import annotations

import dataclasses
import json
import math
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from pyulog.px4 import PX4ULog

from common.config.scenario import load_scenario
from common.logs.ulog import open_ulog, read_topic, tail_record
from gcs.report.metrics import build_metrics
from gcs.run.inprocess import run_scenario
from gcs.run.overrides import apply_overrides
from gcs.run.runio import read_run_logs

from .conftest import ROOT, SCENARIOS, launch, stop
from .test_safety import _fly_keyframe
from .waits import flown_to

CASE1 = SCENARIOS / "case1_figure8.toml"
DURATION_S = 6.0
CONTROL_HZ = 500

# topic -> (expected rate in Hz, fields that must be there)
TRUTH_TOPICS = {
    "dq_truth": (CONTROL_HZ, ("px", "py", "pz", "vx", "qw", "qz", "wx", "rotor0", "tilt5",
                              "landed")),
    "vehicle_local_position_groundtruth": (100, ("x", "y", "z", "vx", "vy", "vz", "heading")),
    "vehicle_attitude_groundtruth": (100, ("q[0]", "q[1]", "q[2]", "q[3]")),
    "vehicle_angular_velocity_groundtruth": (100, ("xyz[0]", "xyz[1]", "xyz[2]")),
}
ONBOARD_TOPICS = {
    "dq_onboard": (CONTROL_HZ, ("pdx", "qdw", "fx", "tz", "rotor_cmd0", "tilt_cmd5",
                                "tilt_raw5", "lnqe_rx", "lnqe_dz", "xie_dz", "step_us")),
    "vehicle_local_position": (50, ("x", "y", "z", "vx", "vy", "vz", "heading", "xy_valid")),
    "vehicle_attitude": (50, ("q[0]", "q[3]")),
    "vehicle_angular_velocity": (50, ("xyz[0]", "xyz[2]")),
    "trajectory_setpoint": (50, ("position[0]", "velocity[2]", "acceleration[1]", "yaw")),
    "vehicle_local_position_setpoint": (50, ("x", "y", "z", "vx", "yaw")),
    "vehicle_attitude_setpoint": (50, ("q_d[0]", "q_d[3]")),
    "vehicle_rates_setpoint": (50, ("roll", "pitch", "yaw")),
    "actuator_motors": (50, ("control[0]", "control[5]")),
    "actuator_servos": (50, ("control[0]", "control[5]")),
    "control_allocator_status": (50, ("torque_setpoint_achieved", "actuator_saturation[0]")),
    "vehicle_status": (2, ("arming_state", "nav_state", "failsafe")),
    "failsafe_flags": (2, ("local_position_invalid", "gcs_connection_lost")),
    "mission_result": (2, ("seq_current", "seq_total", "finished")),
}


def _gcs_run(out: Path, *extra: str) -> dict:
    proc = subprocess.run([sys.executable, "-m", "gcs.cli", "run", str(CASE1), "--out",
                           str(out), "--duration", f"{DURATION_S:g}", *extra], cwd=ROOT,
                          capture_output=True, text=True, timeout=240, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return json.loads((out / "metrics.json").read_text())


@pytest.fixture(scope="module", params=["processes", "in-process"])
def run_dir(request, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("ulog") / request.param
    _gcs_run(out, *(("--in-process",) if request.param == "in-process" else ()))
    return out


def _rate_hz(timestamps: np.ndarray) -> float:
    return (len(timestamps) - 1) / ((timestamps[-1] - timestamps[0]) * 1e-6)


@pytest.mark.timeout(300)
@pytest.mark.parametrize("log, topics", [("truth.ulg", TRUTH_TOPICS),
                                         ("onboard.ulg", ONBOARD_TOPICS)])
def test_pyulog_opens_the_logs_with_px4_topics_at_their_rates(run_dir, log, topics):
    u = open_ulog(run_dir / log)
    assert not u.file_corruption
    assert u.msg_info_dict["ver_hw"] == "SITL"
    for name, (rate, fields) in topics.items():
        d = u.get_dataset(name)
        assert set(fields) <= set(d.data), (name, set(fields) - set(d.data))
        ts = d.data["timestamp"]
        assert np.all(np.diff(ts.astype(np.int64)) > 0), name
        if name in ("vehicle_status", "failsafe_flags", "mission_result"):
            assert _rate_hz(ts) >= rate, name  # at least STATUS_HZ, more at changes
        else:
            assert _rate_hz(ts) == pytest.approx(rate, rel=0.02), name
        if name.startswith("dq_"):
            assert all(d.data[f].dtype == np.float64 for f in fields)
        elif "q[0]" in fields or "x" in fields:
            assert d.data[fields[0]].dtype == np.float32  # PX4's float32


@pytest.mark.timeout(300)
def test_px4_topics_are_ned_frd_views_of_the_float64_log(run_dir):
    """vehicle_local_position and vehicle_attitude are the dq_onboard state in NED/FRD;
    the ground truth topics are dq_truth's."""
    u = open_ulog(run_dir / "onboard.ulg")
    dq = u.get_dataset("dq_onboard").data
    lp = u.get_dataset("vehicle_local_position").data
    att = u.get_dataset("vehicle_attitude").data
    row = {int(t): i for i, t in enumerate(dq["timestamp"])}
    checked = 0
    for k, stamp in enumerate(lp["timestamp_sample"]):
        i = row.get(int(stamp))
        if i is None:
            continue
        checked += 1
        assert lp["x"][k] == pytest.approx(dq["py"][i], abs=1e-5)
        assert lp["y"][k] == pytest.approx(dq["px"][i], abs=1e-5)
        assert lp["z"][k] == pytest.approx(-dq["pz"][i], abs=1e-5)
        q_enu = np.array([dq[c][i] for c in ("qw", "qx", "qy", "qz")])
        q_ned = np.array([att[f"q[{j}]"][k] for j in range(4)])
        # FRD->NED = (ENU->NED) q_enu_flu (FRD->FLU): check on a vector
        h = math.sqrt(0.5)
        expected = _mul(_mul((0.0, h, h, 0.0), q_enu), (0.0, 1.0, 0.0, 0.0))
        assert abs(abs(np.dot(expected, q_ned)) - 1.0) < 1e-6
    assert checked > 100
    # the reference and the outputs, at the control steps they were logged at
    sp = u.get_dataset("trajectory_setpoint").data
    motors = u.get_dataset("actuator_motors").data
    servos = u.get_dataset("actuator_servos").data
    for k, t in enumerate(sp["timestamp"]):
        i = row[int(t)]
        assert [sp[f"position[{j}]"][k] for j in range(3)] == pytest.approx(
            [dq["pdy"][i], dq["pdx"][i], -dq["pdz"][i]], abs=1e-5)
        assert [sp[f"velocity[{j}]"][k] for j in range(3)] == pytest.approx(
            [dq["vdy"][i], dq["vdx"][i], -dq["vdz"][i]], abs=1e-5)
        assert motors["control[0]"][k] == pytest.approx(dq["rotor_cmd0"][i] / 1700.0, abs=1e-6)
        wrapped = (dq["tilt_cmd3"][i] + math.pi) % (2 * math.pi) - math.pi
        assert servos["control[3]"][k] == pytest.approx(wrapped / math.pi, abs=1e-6)
    assert max(abs(v) for v in sp["velocity[2]"]) > 0.5  # the rise: a reference that moves
    truth = open_ulog(run_dir / "truth.ulg")
    dq_t = truth.get_dataset("dq_truth").data
    gt = truth.get_dataset("vehicle_local_position_groundtruth").data
    i = int(np.searchsorted(dq_t["timestamp"], gt["timestamp"][-1]))
    assert gt["z"][-1] == pytest.approx(-dq_t["pz"][i], abs=1e-5)
    assert dq_t["pz"][i] > 1.0  # the vehicle is rising: z up in ENU, down in NED


def _mul(a, b):
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return np.array([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw])


@pytest.mark.timeout(300)
def test_status_topics_say_what_the_vehicle_did(run_dir):
    """Armed in MISSION (PX4's arming_state and nav_state), SITL not HITL, the mission's
    items and progress, no failsafe, the local frame's origin at the FCU's home."""
    from common.logs import px4_topics as px4
    from common.wire.mission_items import PX4_SITL_HOME

    u = open_ulog(run_dir / "onboard.ulg")
    status = u.get_dataset("vehicle_status").data
    assert set(status["arming_state"]) == {px4.ARMING_STATE_ARMED}
    assert set(status["nav_state"]) == {px4.NAVIGATION_STATE_AUTO_MISSION}
    assert not status["failsafe"].any() and not status["hil_state"].any()
    assert status["takeoff_time"][-1] > 0 and status["armed_time"][-1] > 0
    flags = u.get_dataset("failsafe_flags").data
    assert not any(flags[f].any() for f in flags if f != "timestamp")
    result = u.get_dataset("mission_result").data
    assert result["valid"].all() and result["seq_total"][-1] >= 2
    lp = u.get_dataset("vehicle_local_position").data
    home = PX4_SITL_HOME
    assert lp["ref_lat"][-1] == home.lat_deg and lp["ref_lon"][-1] == home.lon_deg
    assert lp["xy_global"].all() and lp["xy_valid"].all()


@pytest.mark.timeout(300)
def test_parameters_and_messages_are_in_the_onboard_log(run_dir):
    u = open_ulog(run_dir / "onboard.ulg")
    params = u.initial_parameters
    assert params["DQ_KPR_X"] == 5.0 and "COM_DIV_POS" in params
    # what Flight Review reads for the vehicle (it showed "unknown type" without)
    assert params["MAV_TYPE"] == 13 and isinstance(params["MAV_TYPE"], int)
    assert PX4ULog(u).get_mav_type() == "Hexarotor" and params["MAV_SYS_ID"] == 1
    texts = [m.message for m in u.logged_messages]
    assert "armed" in texts and "mission started" in texts
    metrics = json.loads((run_dir / "metrics.json").read_text())
    assert texts == [e["text"] for e in metrics["events"]]


@pytest.mark.timeout(300)
def test_metrics_from_the_ulogs_are_the_runs(run_dir):
    """The metrics recomputed from the ULogs equal metrics.json to the last bit."""
    metrics = json.loads((run_dir / "metrics.json").read_text())
    scenario = apply_overrides(load_scenario(CASE1), duration_s=DURATION_S)
    tc, truth, oc, onboard = read_run_logs(run_dir)
    again = build_metrics(scenario, tc, truth, oc, onboard, events=[], wall_time_s=0.0,
                          transport="", lockstep=True, mission_completed=False)
    for key in ("position_error_m", "attitude_error_rad", "samples", "sim_time_s"):
        assert again[key] == metrics[key], key


@pytest.mark.timeout(300)
@pytest.mark.parametrize("sensors", ["truth", "mocap-indoor"])
def test_one_clock_in_the_onboard_log_in_real_time(tmp_path, sensors):
    """Given a real-time run (the simulator's stamps on another process's clock), with the
    exact state or with the estimator on a sensor profile, then every record of onboard.ulg
    is on the FCU's flight clock: a PX4 topic's timestamp_sample is within transit of its
    timestamp (not the processes' start-up apart), dq_onboard is moved by one offset, a
    whole number of control periods, from the states' own stamps (state_time_us), the
    metrics joined on those stamps are metrics.json's, and every state a step took joins
    once. A step that found no newer state than the step before (the simulator late: on a
    loaded machine, 527 of 3,182 steps once) takes the same stamp again and adds no row:
    how often is the machine's, not the FCU's, so it is not judged; that the stamps never
    go back is. With the estimator the stamp is the newest IMU sample at a period's end,
    where the truth log has a row, not the newest sample, which a real-time step may
    follow: keyed by that, 1 to 4 of 3,000 steps joined when the FCU's ticks fell after the
    odd samples of the 1 kHz IMU (tests/unit/test_onboard_log.py makes that case in every
    run)."""
    out = tmp_path / "rt"
    metrics = _gcs_run(out, "--realtime", "--sensors", sensors)
    u = open_ulog(out / "onboard.ulg")
    dq = u.get_dataset("dq_onboard").data
    shift = dq["timestamp"].astype(np.int64) - dq["state_time_us"].astype(np.int64)
    assert len(shift) > 500 and np.all(shift == shift[0]) and shift[0] % 2000 == 0
    keys = dq["state_time_us"].astype(np.int64)
    assert np.all(np.diff(keys) >= 0)  # a step never takes an older state
    assert metrics["samples"] == len(np.unique(keys)), (metrics["samples"], len(keys))
    lp = u.get_dataset("vehicle_local_position").data
    lag_s = (lp["timestamp"].astype(np.int64) - lp["timestamp_sample"].astype(np.int64)) * 1e-6
    # transit and scheduling only: the processes start tens of ms to seconds apart
    assert len(lag_s) > 100 and np.median(np.abs(lag_s)) < 0.02 and np.all(np.abs(lag_s) < 0.25), \
        (np.median(lag_s), lag_s.min(), lag_s.max())
    in_flight = lp["timestamp_sample"][lp["timestamp_sample"] >= dq["timestamp"][0]]
    assert len(in_flight) > 100
    assert set(in_flight.astype(np.int64)) <= set(dq["timestamp"].astype(np.int64))
    scenario = apply_overrides(load_scenario(CASE1), duration_s=DURATION_S, sensors=sensors)
    tc, truth, oc, onboard = read_run_logs(out)
    again = build_metrics(scenario, tc, truth, oc, onboard, events=[], wall_time_s=0.0,
                          transport="", lockstep=False, mission_completed=False,
                          flight_start_us=round(metrics["alignment_s"] * 1e6))
    assert metrics["samples"] > 500
    for key in ("position_error_m", "attitude_error_rad", "samples"):
        assert again[key] == metrics[key], key


@pytest.mark.timeout(300)
def test_in_process_figures_equal_those_before_the_ulog_logs():
    """Case I PID, 30 s and Case II impulse PD, 10 s: the figures the code gave before the
    logs became ULog (DQLOG2), to the last digit printed by json. That code had the paper's
    plain allocation: CA_LAG_COMP 0 (a scenario's [params]) flies it again."""
    before = {
        ("case1_figure8", "pid", 30.0): (
            "completed", (0.0005762165154075127, 0.00016885389368404222, 0.00022987696078111494),
            (7.354488780460163e-06, 8.798853578212958e-07, 1.7560225417177468e-06)),
        ("case2_impulse", "pd", 10.0): (
            "diverged", (10.012295975459937, 0.6164682279603267, 1.9031565363138072),
            (3.140123842243127, 0.683696030505569, 1.2536696253479802)),
    }
    for (name, ctrl, duration), (status, pos, att) in before.items():
        scenario = apply_overrides(load_scenario(SCENARIOS / f"{name}.toml"), controller=ctrl,
                                   duration_s=duration)
        scenario = dataclasses.replace(scenario, params={"CA_LAG_COMP": 0.0})
        m = run_scenario(scenario, logs=False).metrics
        assert m["status"] == status
        assert tuple(m["position_error_m"][k] for k in ("max", "mean", "rmse")) == pos
        assert tuple(m["attitude_error_rad"][k] for k in ("max", "mean", "rmse")) == att


def _contiguous(path: Path, topic: str, period_us: int) -> int:
    """Rows of `topic` in a log whose writer was killed: all readable, no gap, the last one
    the file's last complete record."""
    u = open_ulog(path)
    assert not u.file_corruption
    _, rows = read_topic(path, topic)
    assert len(rows) > 100
    assert np.all(np.diff(rows[:, 0]) == period_us)
    tail = tail_record(path, topic)
    assert tail is not None and tail[1][0] == rows[-1, 0]
    assert np.array_equal(np.array(tail[1][1:]), rows[-1, 1:], equal_nan=True)
    return len(rows)


@pytest.mark.timeout(180)
@pytest.mark.parametrize("victim", ["sitl", "fcu"])
def test_every_complete_record_survives_sigkill(tmp_path, victim):
    """SIGKILL of `sitl` or `fcu` mid-flight: pyulog reads its log to the last complete
    record, rows contiguous at the control period."""
    stack = launch(tmp_path)
    try:
        _fly_keyframe(stack, 0.5, 5.0)
        flown_to(stack, 1.5)  # mid-flight: hundreds of records in each log
        stack.procs[victim].send_signal(signal.SIGKILL)
        stack.procs[victim].wait(timeout=10)
    finally:
        stack.session.close()
        stop(stack.procs)
    log, topic = ("truth.ulg", "dq_truth") if victim == "sitl" else ("onboard.ulg",
                                                                      "dq_onboard")
    _contiguous(tmp_path / log, topic, 1_000_000 // CONTROL_HZ)


LOG_LIMIT_BYTES = 400_000


def _limit_file_size() -> None:
    """In the child: files it writes stop at LOG_LIMIT_BYTES (EFBIG, as a full disk would
    refuse them; CPython ignores SIGXFSZ)."""
    import resource

    resource.setrlimit(resource.RLIMIT_FSIZE, (LOG_LIMIT_BYTES, LOG_LIMIT_BYTES))


@pytest.mark.timeout(180)
def test_a_full_disk_ends_the_log_not_the_flight(tmp_path):
    """The FCU's onboard log hits a full disk in flight: the FCU says so once, flies on
    (armed, answering the simulator), and the log reads to its last complete record."""
    from common.wire.mavlink import MAV

    stack = launch(tmp_path, fcu_preexec=_limit_file_size)
    try:
        _fly_keyframe(stack, 0.5, 5.0)
        text = stack.wait_for(["STATUSTEXT"], lambda m: "onboard log stopped" in m.text, 20.0)
        assert text is not None and text.severity == MAV.MAV_SEVERITY_WARNING
        assert "too large" in text.text
        first = stack.wait_for(["LOCAL_POSITION_NED"])
        later = stack.wait_for(["LOCAL_POSITION_NED"], lambda m: m.time_boot_ms >
                               first.time_boot_ms + 500, 60.0)
        assert later is not None  # simulated time goes on: the FCU still answers
        hb = stack.wait_for(["HEARTBEAT"], lambda m: m.get_srcComponent() == 1)
        assert hb is not None and hb.base_mode & MAV.MAV_MODE_FLAG_SAFETY_ARMED
        assert stack.procs["fcu"].poll() is None
    finally:
        stack.session.close()
        stop(stack.procs)
    path = tmp_path / "onboard.ulg"
    assert path.stat().st_size <= LOG_LIMIT_BYTES
    _contiguous(path, "dq_onboard", 1_000_000 // CONTROL_HZ)


def test_an_unwritable_log_is_a_clear_error(tmp_path):
    """`fcu --onboard-log` and `sitl --truth-log` into a missing folder or onto a full
    device: one line naming the file, exit 2, no traceback."""
    cases = [
        ["fcu.edge.node", "--vehicle", str(ROOT / "config/vehicles/hexa_tilted.toml"), "--gains",
         str(ROOT / "config/gains/pid_eq30.toml"), "--sim", "udpout:127.0.0.1:9", "--gcs",
         "udpout:127.0.0.1:9", "--onboard-log"],
        ["sitl.node", str(CASE1), "--link", "udpin:127.0.0.1:0", "--truth-log"],
    ]
    for argv in cases:
        for target in (tmp_path / "missing" / "x.ulg", Path("/dev/full")):
            proc = subprocess.run([sys.executable, "-m", *argv, str(target)], cwd=ROOT,
                                  capture_output=True, text=True, timeout=60, check=False)
            assert proc.returncode == 2, proc.stderr
            assert str(target) in proc.stderr and "Traceback" not in proc.stderr
