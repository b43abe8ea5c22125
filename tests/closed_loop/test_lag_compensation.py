"""Closed loop: Case I's climb, hover and first seconds of the figure-infinity with the
default actuators (rotor lag, rate-limited tilts), CA_LAG_COMP 1 against 0."""

from __future__ import annotations

import dataclasses

from gcs.run.inprocess import run_scenario

from .conftest import scenario


def _metrics(lag_comp: float) -> dict:
    sc = scenario("case1_figure8", duration_s=25.0)
    sc = dataclasses.replace(sc, params={"CA_LAG_COMP": lag_comp})  # a scenario's [params]
    return run_scenario(sc, logs=False).metrics


def test_lag_compensation_halves_case1_error():
    """Given the first 25 s of Case I (PID, default actuators), then the led allocation's
    maximum position and attitude errors are below half the plain allocation's."""
    on, off = _metrics(1.0), _metrics(0.0)
    assert on["status"] == off["status"] == "completed"
    assert on["position_error_m"]["max"] < 0.5 * off["position_error_m"]["max"]
    assert on["position_error_m"]["rmse"] < 0.5 * off["position_error_m"]["rmse"]
    assert on["attitude_error_rad"]["max"] < 0.5 * off["attitude_error_rad"]["max"]
    assert on["position_error_m"]["max"] < 0.5e-3
