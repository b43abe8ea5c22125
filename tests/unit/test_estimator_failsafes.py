"""The pipeline's estimator failsafes on synthetic sensors (fcu/pipeline.py
`_check_estimator`): poses refused in a row -> LAND; no pose -> HOLD, then LAND; a failed
estimate -> disarm; arming refused until aligned and converged."""

from __future__ import annotations

import math
from pathlib import Path

from common.config.scenario import load_gains, load_vehicle
from fcu.estimator.inputs import ImuInput, PoseInput
from fcu.params import ParamStore, apply_params
from fcu.pipeline import Pipeline

ROOT = Path(__file__).resolve().parents[2]
G = 9.81


class Bench:
    """A pipeline on the estimator fed a vehicle at rest: IMU at 1 kHz, poses at 200 Hz."""

    def __init__(self) -> None:
        gains = load_gains(ROOT / "config/gains/pid_eq30.toml")
        vehicle = load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml")
        self.pipeline = Pipeline(vehicle, gains, 500)
        store = ParamStore(gains)
        for name, value in (("EKF_EVP_NOISE", 2e-4), ("EKF_EV_DELAY", 0.005),
                            ("EKF_EN", 1.0)):
            store.set(name, value)
        apply_params(store, self.pipeline)
        self.t_us = 0
        self.pose_offset = 0.0
        self.poses = True

    def run(self, seconds: float) -> None:
        p = self.pipeline
        for _ in range(round(seconds * 1000)):
            self.t_us += 1000
            if self.poses and self.t_us % 5000 == 0:  # captured 5 ms ago (its latency)
                p.on_pose(PoseInput(self.t_us - 5000, (self.pose_offset, 0.0, 0.0),
                                    (1.0, 0.0, 0.0, 0.0), 4e-8, 1e-6))
            p.on_imu(ImuInput(self.t_us, (0.0, 0.0, 0.0), (0.0, 0.0, G)))
            if self.t_us % 2000 == 0:
                p.step(self.t_us, 0.002)

    def texts(self) -> list[str]:
        return [e.text for e in self.pipeline.events]


def test_arming_waits_for_alignment_then_flies():
    b = Bench()
    b.run(0.5)
    code, why = b.pipeline.arm()
    assert code == 1 and "estimator not aligned" in why  # MAV_RESULT_TEMPORARILY_REJECTED
    assert b.pipeline.needs_time
    b.run(1.0)
    assert not b.pipeline.needs_time and b.pipeline.estimator_ready
    assert b.pipeline.arm()[0] == 0 and b.pipeline.armed


def test_poses_refused_in_a_row_land():
    b = Bench()
    b.run(1.5)
    assert b.pipeline.arm()[0] == 0
    b.run(0.2)
    assert not b.pipeline.failsafe
    b.pose_offset = 0.5  # the pose source jumps 0.5 m: every pose fails the gate
    b.run(0.2)
    st = b.pipeline.estimator.status()
    assert st.rejected_in_row >= 20
    assert b.pipeline.failsafe == "estimator inconsistent"
    assert b.pipeline.commander.mode.name == "LAND"
    assert any("estimator inconsistent" in t and "LAND" in t for t in b.texts())


def test_pose_loss_dead_reckons_then_holds_then_lands():
    b = Bench()
    b.run(1.5)
    assert b.pipeline.arm()[0] == 0
    b.poses = False
    b.run(0.9)  # within COM_POS_LOSS_T = 1 s: dead-reckoning, nothing said
    assert not b.pipeline.failsafe
    b.run(0.3)
    assert b.pipeline.failsafe == "pose source lost"
    assert b.pipeline.commander.mode.name == "HOLD"
    b.run(2.0)  # COM_POS_LAND_T = 2 s later
    assert b.pipeline.commander.mode.name == "LAND"
    texts = b.texts()
    hold = texts.index("failsafe: pose source lost: HOLD")
    assert texts.index("failsafe: pose source lost: LAND") > hold
    b.poses = True
    b.run(0.1)
    assert "pose source regained" in b.texts() and b.pipeline.failsafe == ""
    assert b.pipeline.commander.mode.name == "LAND"  # the mode stays


def test_a_failed_estimate_disarms():
    b = Bench()
    b.run(1.5)
    assert b.pipeline.arm()[0] == 0
    est = b.pipeline.estimator
    assert est is not None
    est._P[0, 0] = math.inf  # a covariance blown up
    b.run(0.004)
    assert not b.pipeline.armed and b.pipeline.failsafe == "estimator failed"
    assert any("estimator failed" in t for t in b.texts())


def test_alignment_gives_up_after_a_minute_without_poses():
    """No pose source: simulated time runs for the alignment at most ALIGN_MAX_S, then the
    FCU says so once and stops asking for time (lockstep waits, as for a silent sensor)."""
    b = Bench()
    b.poses = False
    b.run(59.0)
    assert b.pipeline.needs_time
    b.run(1.1)
    assert not b.pipeline.needs_time and not b.pipeline.needs_time
    assert b.texts().count("estimator not aligned in 60 s: waiting") == 1
    assert b.pipeline.arm()[0] == 1
