"""Missions the vehicle can fly, and landings that end on the ground, disarmed: the mission
of config/missions/tour.toml (takeoff, 2 m waypoint legs at the default 2 m/s, a keyframe,
the figure-infinity, a landing) flown by the FCU's pipeline in-process."""

from __future__ import annotations

import numpy as np

from common.config import load_scenario
from gcs.inprocess import run_scenario

from .conftest import SCENARIOS


def test_tour_is_flown_within_the_envelope_and_lands_disarmed():
    """Given the tour mission (its 2 m legs at 2 m/s would need 11.5 m/s^2), when flown, then
    the legs are stretched (no rotor saturates, tracking within centimetres), the mission
    completes, and the landing disarms on the ground within 3 s of touchdown, no crash."""
    result = run_scenario(load_scenario(SCENARIOS / "mission_tour.toml"))
    m = result.metrics
    assert m["status"] == "completed" and m["mission_completed"], m["events"]
    assert m["saturated_steps"] == 0
    assert m["position_error_m"]["max"] < 0.2
    t, z, landed = result.truth_col("time_us", "pz", "landed").T
    touchdown = t[(landed > 0.5) & (t > 5e6)][0] * 1e-6
    disarm = [e["t_s"] for e in m["events"] if e["text"] == "landed: disarmed"]
    assert len(disarm) == 1 and touchdown - 0.1 <= disarm[0] <= touchdown + 3.0
    after = t * 1e-6 > disarm[0] + 0.5
    assert np.all(z[after] == 0.0) and np.all(landed[after] > 0.5)  # resting, rotors off
    rotors = result.truth_col(*(f"rotor{i}" for i in range(6)))
    assert np.all(rotors[t * 1e-6 > disarm[0] + 1.0] < 1.0)
