"""The estimator's parameters (EKF_*, IMU_GYRO_CUTOFF, COM_POS_*) reach the pipeline, and
the ones that change the state source are refused while armed."""

from __future__ import annotations

from pathlib import Path

import pytest

from common.config.scenario import load_gains, load_vehicle
from fcu.params import ParamError, ParamStore, apply_params
from fcu.pipeline import Pipeline

ROOT = Path(__file__).resolve().parents[2]


def _pipeline() -> tuple[Pipeline, ParamStore]:
    gains = load_gains(ROOT / "config/gains/pid_eq30.toml")
    pipeline = Pipeline(load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml"), gains, 500)
    store = ParamStore(gains)
    apply_params(store, pipeline)
    return pipeline, store


def test_parameters_reach_the_estimator_and_the_failsafes():
    pipeline, store = _pipeline()
    assert pipeline.estimator is None  # EKF_EN 0: the exact state input
    for name, value in (("EKF_EV_DELAY", 0.015), ("EKF_GYR_NOISE", 0.05),
                        ("EKF_ACC_NOISE", 0.5), ("EKF_EVP_NOISE", 0.003),
                        ("EKF_EVA_NOISE", 0.004), ("EKF_EV_GATE", 3.0),
                        ("EKF_GYR_B_NOISE", 0.002), ("EKF_ACC_B_NOISE", 0.01),
                        ("EKF_GATE_N", 7.0), ("COM_POS_LOSS_T", 0.7), ("COM_POS_LAND_T", 4.0),
                        ("IMU_GYRO_CUTOFF", 60.0), ("EKF_EN", 1.0)):
        store.set(name, value)
    apply_params(store, pipeline)
    est = pipeline.estimator
    assert est is not None
    st = est.settings
    got = (st.pose_delay_s, st.gyro_noise_rad_s, st.accel_noise_m_s2, st.pose_pos_noise_m,
           st.pose_att_noise_rad, st.pose_gate_sd, st.gyro_bias_noise_rad_s2,
           st.accel_bias_noise_m_s3, st.gravity_m_s2)
    assert got == pytest.approx((0.015, 0.05, 0.5, 0.003, 0.004, 3.0, 0.002, 0.01,
                                 pipeline.vehicle.gravity_m_s2), rel=1e-6)
    fs = pipeline.settings
    assert (fs.gate_failures, fs.pose_loss_s, fs.pose_loss_land_s) == \
        pytest.approx((7, 0.7, 4.0), rel=1e-6)
    assert pipeline.rate_filter.cutoff_hz == pytest.approx(60.0)
    store.set("EKF_EN", 0.0)
    apply_params(store, pipeline)
    assert pipeline.estimator is None


def test_state_source_parameters_are_refused_while_armed():
    _, store = _pipeline()
    store.set("EKF_EV_DELAY", 0.01, armed=False)
    for name, value in (("EKF_EN", 1.0), ("EKF_EV_DELAY", 0.02), ("IMU_GYRO_CUTOFF", 20.0)):
        with pytest.raises(ParamError, match="only disarmed"):
            store.set(name, value, armed=True)
    assert store.values["EKF_EV_DELAY"] == pytest.approx(0.01)
    store.set("EKF_EV_DELAY", store.values["EKF_EV_DELAY"], armed=True)  # unchanged: fine
    store.set("COM_POS_LOSS_T", 2.0, armed=True)  # a failsafe time may change in flight
