"""Closed loop on the estimator (mocap-indoor): the rate the controller damps with is the
gyro through IMU_GYRO_CUTOFF's low-pass, which takes the IMU's white noise out of the
commanded torque."""

from __future__ import annotations

import dataclasses

from common.config.sensors import resolve_sensor_profile
from gcs.run.inprocess import run_scenario

from .conftest import scenario


def _attitude_rmse(cutoff_hz: float) -> float:
    sc = dataclasses.replace(scenario("case1_figure8", duration_s=6.0),
                             sensors=resolve_sensor_profile("mocap-indoor"),
                             params={"IMU_GYRO_CUTOFF": cutoff_hz})
    m = run_scenario(sc, logs=False).metrics
    assert m["status"] == "completed"
    assert m["fcu_params"]["IMU_GYRO_CUTOFF"] == cutoff_hz
    return float(m["attitude_error_rad"]["rmse"])


def test_filtered_rate_lowers_the_attitude_error():
    """Given the climb of Case I on mocap-indoor sensors, then with the 40 Hz low-pass the
    attitude error RMSE is clearly below the unfiltered rate's."""
    filtered, raw = _attitude_rmse(40.0), _attitude_rmse(0.0)
    assert filtered < 0.8 * raw, (filtered, raw)
