"""Flights on the estimator (a sensor profile, an error-state EKF in the FCU) with injected
sensor faults ([[sensor_fault]]), in-process and through the processes: arming waits for the
alignment, a short pose gap is bridged, a long one gives HOLD then LAND, a gyro bias step is
estimated, NaN in a sensor frame never reaches the actuators nor stops the lockstep, and a
seed gives one flight, sample for sample, however it is flown.

Case I (on the ground, climb 0-10 s to 5 m, hover to 20 s) with mocap-indoor; the faults
come in the hover at 12 s of flight time.
"""

from __future__ import annotations

import dataclasses
import json
import math
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import gcs.run.inprocess as inprocess
from common.config.scenario import SensorFault, load_scenario
from common.config.sensors import resolve_sensor_profile
from common.links import free_port
from common.logs.columns import ONBOARD_COLUMNS, TRUTH_COLUMNS
from common.logs.ulog import read_topic
from common.wire.mavlink import MAV
from common.wire.simlink import (
    HIL_ACTUATOR_CONTROLS_ID,
    HilSensor,
    pack_hil_sensor,
    pack_odometry,
    split_frames,
    unpack_actuator_controls,
)
from fcu.edge.onboard_log import DQ_ONBOARD_COLUMNS
from gcs.report.metrics import attitude_error_rad, join_logs
from gcs.run.inprocess import run_scenario
from gcs.run.overrides import apply_overrides
from gcs.run.runio import RunResult
from gcs.vehicle_link.params import param_set
from gcs.vehicle_link.session import Session
from sitl.plant import Plant, initial_state
from sitl.sensor_feed import SensorFeed

from .conftest import PACE, PID, ROOT, SCENARIOS, VEHICLE, launch, start, stop

M = MAV
CASE1 = SCENARIOS / "case1_figure8.toml"
PROFILE = "mocap-indoor"
FIGURES = ("position_error_m", "attitude_error_rad", "estimation_error", "samples",
           "sim_time_s", "status", "failsafe", "events", "seed", "sensors", "alignment_s")


def _fly(duration_s: float, *faults: SensorFault, seed: int = 1,
         params: dict[str, float] | None = None) -> RunResult:
    sc = apply_overrides(load_scenario(CASE1), sensors=PROFILE, seed=seed,
                         duration_s=duration_s)
    return run_scenario(dataclasses.replace(sc, sensor_faults=faults,
                                            params={**sc.params, **(params or {})}),
                        logs=False)


@dataclasses.dataclass
class Flight:
    """A run's truth and onboard rows joined by time, on the flight's clock."""

    t_s: np.ndarray  # flight time
    est_pos_m: np.ndarray  # |estimated - true position|
    est_att_rad: np.ndarray  # estimated vs true attitude
    track_m: np.ndarray  # |true - desired position|
    rate_residual: np.ndarray  # estimated (bias-corrected) - true body rate, FLU
    z_m: np.ndarray  # true height

    @classmethod
    def of(cls, r: RunResult) -> Flight:
        t, tj, oj = join_logs(TRUTH_COLUMNS, r.truth, ONBOARD_COLUMNS, r.onboard)

        def tc(*n):
            return tj[:, [TRUTH_COLUMNS.index(c) for c in n]]

        def oc(*n):
            return oj[:, [ONBOARD_COLUMNS.index(c) for c in n]]

        p = tc("px", "py", "pz")
        return cls(t * 1e-6 - r.metrics["alignment_s"],
                   np.linalg.norm(oc("px", "py", "pz") - p, axis=1),
                   attitude_error_rad(oc("qw", "qx", "qy", "qz"), tc("qw", "qx", "qy", "qz")),
                   np.linalg.norm(p - oc("pdx", "pdy", "pdz"), axis=1),
                   oc("wx", "wy", "wz") - tc("wx", "wy", "wz"), p[:, 2])

    def between(self, a: float, b: float = math.inf) -> np.ndarray:
        return (self.t_s >= a) & (self.t_s < b)


def _texts(r: RunResult) -> list[str]:
    return [e["text"] for e in r.metrics["events"]]


# ---------------------------------------------------------------------------- in-process


def test_short_pose_gap_is_bridged_without_failsafe():
    """mocap off 0.5 s at 12 s (hover at 5 m): the run completes with no failsafe, the
    estimate dead-reckons on the IMU (error grows, bounded), and is back below 1 mm within
    1 s after the poses return."""
    r = _fly(14.5, SensorFault("mocap_off", 12.0, 12.5))
    f = Flight.of(r)
    m = r.metrics
    assert m["status"] == "completed" and m["failsafe"] == ""
    assert _texts(r) == ["armed", "mission started"]
    gap = f.between(12.0, 12.5)
    assert f.est_pos_m[f.between(10.0, 12.0)].max() < 1e-3
    # without poses the error grows (the cut happened) but stays bounded (seed 1: 4.3 mm)
    assert 1e-3 < f.est_pos_m[gap].max() < 0.02
    assert f.track_m[gap].max() < 0.03
    assert f.est_pos_m[f.between(13.5)].max() < 1e-3
    assert f.t_s[-1] == pytest.approx(14.5)


def test_long_pose_gap_holds_then_lands():
    """mocap off 5 s at 12 s: dead-reckoning COM_POS_LOSS_T = 1 s, then HOLD, then LAND
    COM_POS_LAND_T = 2 s later ("pose source lost"); the run is a failsafe by that name and
    the vehicle comes down (at up to MIS_LAND_SPD 1 m/s: 4.9 m takes 9.2 s, 5 s are left)."""
    r = _fly(20.0, SensorFault("mocap_off", 12.0, 17.0), params={"MIS_LAND_SPD": 1.0})
    m = r.metrics
    assert m["status"] == "failsafe" and "pose source lost" in m["failsafe"]
    fs = [e for e in m["events"] if e["kind"] == "failsafe"]
    assert [e["text"] for e in fs] == ["failsafe: pose source lost: HOLD",
                                       "failsafe: pose source lost: LAND"]
    hold, land = (e["t_s"] - m["alignment_s"] for e in fs)
    assert hold == pytest.approx(13.0, abs=0.02)  # last pose captured just before 12 s
    assert land - hold == pytest.approx(2.0, abs=0.01)
    assert "pose source regained" in _texts(r)
    f = Flight.of(r)
    assert f.z_m[f.between(10.0, hold)].min() > 4.9  # held its height until then
    z_land = f.z_m[np.argmax(f.t_s >= land)]
    end = f.t_s >= f.t_s[-1] - 0.5
    assert f.z_m[-1] < z_land - 2.0  # came down (seed 1: 4.9 m -> 2.5 m)
    assert f.z_m[end][-1] < f.z_m[end][0] - 0.2 or r.truth[-1, TRUTH_COLUMNS.index("landed")]


def test_gyro_bias_step_is_estimated():
    """20 mrad/s added to the gyro's x (10 mrad/s on -z) at 12 s: the bias-corrected rate
    the FCU flies on is off by the step at first and back within 2 mrad/s after 3 s (the
    estimator took the step into its gyro bias); the attitude error stays below 5 mrad."""
    step = (0.02, 0.0, -0.01)
    r = _fly(17.0, SensorFault("gyro_bias_step", 12.0, amplitude=step))
    assert r.metrics["status"] == "completed" and r.metrics["failsafe"] == ""
    f = Flight.of(r)
    before = f.rate_residual[f.between(10.0, 12.0)].mean(axis=0)
    first = f.rate_residual[f.between(12.0, 12.2)].mean(axis=0)
    after = f.rate_residual[f.between(15.0, 17.0)].mean(axis=0)
    assert np.abs(before).max() < 2e-3
    assert first == pytest.approx(step, abs=5e-3)  # the step reached the FCU
    assert np.abs(after).max() < 2e-3
    assert f.est_att_rad[f.between(15.0)].max() < 5e-3
    assert f.est_att_rad.max() < 5e-3


def test_nan_in_sensor_frames_never_reaches_the_actuators(monkeypatch):
    """10 ms of IMU samples with NaN (gyro and accelerometer) and 50 ms of poses with NaN:
    the FCU gets them (counted at its inputs), the estimator skips them (the state holds
    still over the NaN samples), the run completes without a failsafe and every logged
    command and state is finite."""
    seen = {"imu_nan": 0, "pose_nan": 0}
    imu_in, pose_in = inprocess.imu_for_fcu, inprocess.pose_for_fcu

    def imu(h):
        seen["imu_nan"] += not math.isfinite(sum((*h.gyro_frd_rad_s, *h.acc_frd_m_s2)))
        return imu_in(h)

    def pose(o):
        seen["pose_nan"] += not math.isfinite(sum((*o.p_ned_m, *o.q_ned_frd)))
        return pose_in(o)

    monkeypatch.setattr(inprocess, "imu_for_fcu", imu)
    monkeypatch.setattr(inprocess, "pose_for_fcu", pose)
    r = _fly(13.5, SensorFault("imu_nan", 12.0, 12.01), SensorFault("pose_nan", 12.5, 12.55))
    assert seen == {"imu_nan": 10, "pose_nan": 10}
    m = r.metrics
    assert m["status"] == "completed" and m["failsafe"] == ""
    assert _texts(r) == ["armed", "mission started"]
    assert np.isfinite(r.onboard).all() and np.isfinite(r.truth).all()
    assert m["estimation_error"]["position_m"]["max"] < 2e-3
    # the periods answered on NaN samples fly on the last good estimate
    state = [ONBOARD_COLUMNS.index(c) for c in ("px", "py", "pz", "qw", "qx", "qy", "qz")]
    f = Flight.of(r)
    rows = r.onboard[np.searchsorted(r.onboard[:, 0], r.truth[0, 0]):]
    t = rows[:, 0] * 1e-6 - m["alignment_s"]
    # (the estimate at the newest good sample, 11.999 s) until the samples are good again
    held = rows[(t >= 12.0 - 1e-9) & (t < 12.01 - 1e-9)][:, state]
    after = rows[np.searchsorted(t, 12.01 - 1e-9), state]
    assert len(held) == 5 and (held == held[0]).all() and (after != held[0]).any()
    assert f.est_pos_m[f.between(12.0)].max() < 2e-3


# ---------------------------------------------------------------------------- processes


def _fault_scenario(path: Path, duration_s: float = 3.0, seed: int = 3) -> Path:
    """Case I for `duration_s` with mocap-indoor, a pose gap at 1.0-1.3 s and a gyro bias
    step at 2.0 s (a file: the simulator process reads the scenario)."""
    config = ROOT / "config"
    path.write_text(f"""name = "case1_faults"
duration_s = {duration_s!r}
controller = "pid"
vehicle = "{config}/vehicles/hexa_tilted.toml"
seed = {seed}
sensors = "{PROFILE}"

[gains]
pid = "{config}/gains/pid_eq30.toml"
pd = "{config}/gains/pd_eq33.toml"

[initial]
start = "ground"

[trajectory]
kind = "case1_figure8"

[[sensor_fault]]
kind = "mocap_off"
start_s = 1.0
end_s = 1.3

[[sensor_fault]]
kind = "gyro_bias_step"
start_s = 2.0
amplitude = [0.005, 0.0, 0.0]
""")
    return path


def _without_step_us(rows: np.ndarray) -> np.ndarray:
    out = rows.copy()
    out[:, ONBOARD_COLUMNS.index("step_us")] = 0.0
    return out


def test_a_seed_is_one_flight_through_processes_and_in_process(tmp_path):
    """`gcs run FILE --seed 7` through the processes and run_scenario with seed 7 (twice):
    identical metrics and float64 truth and onboard topics sample for sample (step_us
    aside), faults included; without the faults the same up to the first one; another
    seed, other figures."""
    path = _fault_scenario(tmp_path / "faults.toml")
    out = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-m", "gcs.cli", "run", str(path), "--seed", "7",
                           "--out", str(out)], cwd=ROOT, capture_output=True, text=True,
                          timeout=300, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    m = json.loads((out / "metrics.json").read_text())
    assert m["seed"] == 7 and m["sensors"] == PROFILE and m["transport"] == "udp"
    sc = apply_overrides(load_scenario(path), seed=7)
    a, b = run_scenario(sc, logs=False), run_scenario(sc, logs=False)
    for key in FIGURES:
        assert m[key] == a.metrics[key] == b.metrics[key], key
    assert np.array_equal(a.truth, b.truth)
    assert np.array_equal(_without_step_us(a.onboard), _without_step_us(b.onboard))
    truth_cols, truth = read_topic(out / "truth.ulg", "dq_truth")
    onboard_cols, onboard = read_topic(out / "onboard.ulg", "dq_onboard")
    assert tuple(truth_cols) == TRUTH_COLUMNS and tuple(onboard_cols) == DQ_ONBOARD_COLUMNS
    assert truth.shape == a.truth.shape and np.array_equal(truth, a.truth)
    onboard = onboard[:, :len(ONBOARD_COLUMNS)]  # in-process rows have no state stamp
    assert onboard.shape == a.onboard.shape
    assert np.array_equal(_without_step_us(onboard), _without_step_us(a.onboard))

    plain = run_scenario(dataclasses.replace(sc, sensor_faults=()), logs=False)
    t0_us = round(a.metrics["alignment_s"] * 1e6)
    upto = a.truth[:, 0] <= t0_us + 1_000_000  # the first fault at 1.0 s
    assert np.array_equal(plain.truth[upto], a.truth[upto])
    assert not np.array_equal(plain.truth, a.truth)
    assert plain.metrics["estimation_error"] != a.metrics["estimation_error"]

    other = run_scenario(apply_overrides(sc, seed=8), logs=False).metrics
    assert other["seed"] == 8
    assert other["position_error_m"] != a.metrics["position_error_m"]
    assert other["estimation_error"] != a.metrics["estimation_error"]


def test_arming_is_refused_until_the_estimator_has_aligned(tmp_path):
    """With EKF_EN = 1, ARM is TEMPORARILY_REJECTED with the reason in a STATUSTEXT while the
    estimator has no aligned estimate (the simulator not yet running), and ACCEPTED once the
    simulator's sensors (mocap-indoor, lockstep) have aligned it."""
    sim_port, gcs_port = free_port(), free_port()
    procs: dict[str, subprocess.Popen] = {}
    s = Session(f"udpin:127.0.0.1:{gcs_port}")
    try:
        procs["fcu"] = start("fcu", ["fcu.edge.node", "--vehicle", str(VEHICLE), "--gains",
        str(PID),
                                     "--sim", f"udpout:127.0.0.1:{sim_port}", "--gcs",
                                     f"udpout:127.0.0.1:{gcs_port}"], tmp_path)
        s.wait_vehicle(timeout=15.0)
        for name, value in (("EKF_EV_DELAY", 0.005), ("EKF_EN", 1.0)):
            assert param_set(s, name, value)[0] == pytest.approx(value)
        ack = s.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
        assert ack == M.MAV_RESULT_TEMPORARILY_REJECTED
        assert any("estimator" in t and "not aligned" in t for t in s.last_texts), s.last_texts
        procs["sitl"] = start("sitl", ["sitl.node", str(CASE1), "--link",
                                       f"udpin:127.0.0.1:{sim_port}", "--sensors", PROFILE,
                                       "--seed", "2", *PACE], tmp_path)
        deadline = time.monotonic() + 30.0
        refusals = 0
        while ack != M.MAV_RESULT_ACCEPTED and time.monotonic() < deadline:
            time.sleep(0.2)
            ack = s.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
            refusals += ack == M.MAV_RESULT_TEMPORARILY_REJECTED
        assert ack == M.MAV_RESULT_ACCEPTED, (s.last_texts, (tmp_path / "fcu.log").read_text())
        hb = s.recv(["HEARTBEAT"], timeout=3.0)
        assert hb is not None and hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
        est = s.recv(["ESTIMATOR_STATUS"], timeout=3.0)
        assert est is not None
        # what the estimate says of itself: a solution with position, accuracies of mm
        want = M.ESTIMATOR_ATTITUDE | M.ESTIMATOR_POS_HORIZ_REL | M.ESTIMATOR_VELOCITY_HORIZ
        assert est.flags & want == want and not est.flags & M.ESTIMATOR_ACCEL_ERROR
        assert 0.0 < est.pos_horiz_accuracy < 0.002 and 0.0 < est.pos_vert_accuracy < 0.002
        odo = s.recv(["ODOMETRY"], timeout=3.0)
        assert odo is not None and odo.estimator_type == M.MAV_ESTIMATOR_TYPE_AUTOPILOT
        assert 0.0 < odo.pose_covariance[0] < 4e-6 and 0.0 < odo.pose_covariance[15] < 4e-6
    finally:
        s.close()
        stop(procs)


def _fcu_sim_address(log: Path) -> tuple[str, int]:
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline:
        for line in log.read_text(errors="replace").splitlines():
            if "sim port" in line:
                return "127.0.0.1", int(line.rsplit(" ", 1)[1])
        time.sleep(0.05)
    raise AssertionError(log.read_text())


class _WireSim:
    """A simulator of our own on a socket: the sensor feed's frames of each period sent to
    the FCU (the NaN ones counted), its HIL_ACTUATOR_CONTROLS awaited."""

    def __init__(self, sim: socket.socket, fcu: tuple[str, int], feed: SensorFeed) -> None:
        self.sim, self.fcu, self.feed = sim, fcu, feed
        self.seq = self.nan_imu = self.nan_pose = 0

    def send(self, states) -> int:
        parts = []
        for msg in self.feed.period(states):
            self.seq = (self.seq + 1) & 0xFF
            if isinstance(msg, HilSensor):
                self.nan_imu += not math.isfinite(sum(msg.gyro_frd_rad_s))
                parts.append(pack_hil_sensor(msg, self.seq, 1, 200))
            else:
                self.nan_pose += not math.isfinite(sum(msg.p_ned_m))
                parts.append(pack_odometry(msg, self.seq, 1, 200))
        self.sim.sendto(b"".join(parts), self.fcu)
        return states[-1].time_us

    def answer(self, t_us: int):
        end = time.monotonic() + 1.0
        while time.monotonic() < end:
            try:
                data, _ = self.sim.recvfrom(65535)
            except TimeoutError:
                continue
            for f in split_frames(data)[0]:
                if f.msg_id == HIL_ACTUATOR_CONTROLS_ID:
                    a = unpack_actuator_controls(f.payload)
                    if a.time_usec == t_us:
                        return a
        return None


def _periods_until_unanswered(wire: _WireSim, state) -> tuple[list[int], list[int]]:
    """Control periods sent until one is not answered (or 3 s): the answered periods' times
    (each finite and disarmed), then the first unanswered one's."""
    answered: list[int] = []
    unanswered: list[int] = []
    t_us = wire.send([state])
    while t_us <= 3_000_000:
        a = wire.answer(t_us)
        if a is None:
            unanswered.append(t_us)
            break  # aligned: the world waits for the flight
        assert all(math.isfinite(c) for c in a.controls)
        assert not a.mode & M.MAV_MODE_FLAG_SAFETY_ARMED
        answered.append(t_us)
        states = []
        for _ in range(2):
            state = state._replace(time_us=state.time_us + 1000)
            states.append(state)
        t_us = wire.send(states)
    return answered, unanswered


def test_nan_frames_on_the_wire_are_skipped_and_the_lockstep_answers(tmp_path):
    """A simulator of our own sends an FCU (EKF_EN = 1, lockstep) the sensors of a vehicle at
    rest, aligning, with 50 ms of ODOMETRY poses carrying NaN and then 10 ms of HIL_SENSOR
    carrying NaN: every control period's sample is answered until the estimator has
    aligned, NaN ones included (time echoed, finite disarmed outputs); the NaN poses are
    counted as ignored, and the estimator, never stepped on NaN, aligns and converges: ARM
    is accepted."""
    sim = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sim.bind(("127.0.0.1", 0))
    sim.settimeout(0.5)
    stats = tmp_path / "fcu_stats.json"
    stack = launch(tmp_path, sitl=False, sim_port=sim.getsockname()[1],
                   fcu_args=("--stats", str(stats)))
    try:
        s = stack.session
        for name, value in (("EKF_EV_DELAY", 0.005), ("EKF_EN", 1.0)):
            assert param_set(s, name, value)[0] == pytest.approx(value)
        fcu = _fcu_sim_address(tmp_path / "fcu.log")
        scenario = load_scenario(CASE1)
        plant = Plant(scenario.vehicle, dt_us=1000)
        feed = SensorFeed(resolve_sensor_profile(PROFILE), 5, plant, 2000)
        feed.start_flight(0, (SensorFault("pose_nan", 0.2, 0.25),
                              SensorFault("imu_nan", 0.3, 0.31)))
        wire = _WireSim(sim, fcu, feed)
        answered, unanswered = _periods_until_unanswered(wire, initial_state(scenario, plant))
        assert wire.nan_imu == 10 and wire.nan_pose == 10
        assert answered == list(range(0, answered[-1] + 1, 2000))
        assert {300_000, 302_000, 304_000, 306_000, 308_000} <= set(answered)
        # aligned (not answered any more: the world waits for the flight) after the NaN,
        # within align_time_s = 1 s of still samples: NaN in the estimator's alignment
        # window would have restarted it (1.4 s).
        assert answered[-1] >= 308_000 and unanswered == [answered[-1] + 2000]
        assert answered[-1] < 1.2e6
        ack = s.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
        assert ack == M.MAV_RESULT_ACCEPTED, s.describe(ack)
    finally:
        stack.session.close()
        stop(stack.procs)
        sim.close()
    assert json.loads(stats.read_text())["ignored_messages"] >= 10


def test_refused_imu_samples_do_not_shorten_the_alignment():
    """At rest, 10 ms of NaN IMU samples at 0.3 s: the estimator still needs its 1 s
    (align_time_s) of still samples before it is aligned."""
    sc = apply_overrides(load_scenario(CASE1), sensors=PROFILE, seed=5)
    assert sc.sensors is not None
    pipeline, _ = inprocess.fcu_pipeline(sc)
    plant = Plant(sc.vehicle, dt_us=1000)
    feed = SensorFeed(sc.sensors, 5, plant, 2000)
    feed.start_flight(0, (SensorFault("imu_nan", 0.3, 0.31),))
    state = initial_state(sc, plant)
    inprocess.feed_fcu(pipeline, feed.period([state]))
    while pipeline.needs_time and state.time_us < 3_000_000:
        pipeline.step(state.time_us, 0.002)
        states = []
        for _ in range(2):
            state = state._replace(time_us=state.time_us + 1000)
            states.append(state)
        inprocess.feed_fcu(pipeline, feed.period(states))
    assert pipeline.estimator is not None
    assert pipeline.estimator.status().imu_ignored == 10
    assert state.time_us >= 1_000_000


# ---------------------------------------------------------------------------- command line


def _gcs(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "gcs.cli", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=120, check=False)


def test_seed_and_sensors_reach_the_run(tmp_path):
    out = tmp_path / "run"
    proc = _gcs("run", str(CASE1), "--in-process", "--sensors", PROFILE, "--seed", "5",
                "--duration", "1", "--out", str(out))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    m = json.loads((out / "metrics.json").read_text())
    assert m["seed"] == 5 and m["sensors"] == PROFILE and "estimation_error" in m
    ref = _fly(1.0, seed=5).metrics
    assert m["estimation_error"] == ref["estimation_error"]
    assert m["position_error_m"] == ref["position_error_m"]


@pytest.mark.parametrize("argv", [
    ("gcs.cli", "run", str(CASE1), "--sensors", "nosuch"),
    ("gcs.cli", "run", str(CASE1), "--in-process", "--sensors", "nosuch"),
    ("gcs.cli", "run", str(CASE1), "--seed", "-1"),
    ("gcs.cli", "run", str(CASE1), "--seed", "x"),
    ("sitl.node", str(CASE1), "--sensors", "nosuch"),
    ("sitl.node", str(CASE1), "--seed", "-1"),
], ids=["gcs-sensors", "gcs-in-process-sensors", "gcs-seed", "gcs-seed-text", "sitl-sensors",
        "sitl-seed"])
def test_bad_sensors_or_seed_exit_2_with_one_line(tmp_path, argv):
    proc = subprocess.run([sys.executable, "-m", *argv, *(("--out", str(tmp_path / "o"))
                                                          if argv[0] == "gcs.cli" else ())],
                          cwd=ROOT, capture_output=True, text=True, timeout=60, check=False)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and ("nosuch" in lines[0] or "seed" in lines[0]), proc.stderr
    assert "Traceback" not in proc.stderr


def test_a_fault_without_a_sensor_profile_exits_2(tmp_path):
    path = _fault_scenario(tmp_path / "faults.toml")
    path.write_text(path.read_text().replace(f'sensors = "{PROFILE}"\n', ""))
    proc = _gcs("run", str(path), "--in-process", "--out", str(tmp_path / "o"))
    assert proc.returncode == 2 and "faults need a sensor profile" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
