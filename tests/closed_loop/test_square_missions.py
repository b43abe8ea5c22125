"""The 2 m square (config/scenarios/mission_square.toml) on both vehicle files, in-process:
at up to 3.75 m/s (planned in 1 s) its legs are stretched until the tilt servos can follow
and it is flown within 5 cm and 3 deg; at up to 1.875 m/s (2 s) it flies as planned (a leg is
stretched by 1 % at most)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from common.config.scenario import load_vehicle
from fcu.mission.executor import MissionExecutor
from fcu.mission.limits import MissionLimits
from gcs.run.inprocess import fcu_pipeline, run_scenario
from gcs.run.scenario_mission import scenario_mission

from .conftest import ROOT, scenario

VEHICLES = ["hexa_tilted", "hexa_planar"]


def _square(vehicle: str, cruise_m_s: float):
    sc = scenario("mission_square", duration_s=24.0,
                  vehicle=load_vehicle(ROOT / "config" / "vehicles" / f"{vehicle}.toml"))
    return dataclasses.replace(sc, params={**sc.params, "MIS_CRUISE_SPD": cruise_m_s})


def _legs(sc, limits: MissionLimits) -> list[float]:
    ex = MissionExecutor(scenario_mission(sc), limits)
    ex.start(0.0, (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))
    return [t1 - t0 for _seq, t0, t1 in ex.schedule[1:]]


@pytest.mark.parametrize("vehicle", VEHICLES)
@pytest.mark.parametrize("cruise_m_s", [3.75, 1.875])
def test_square_is_flown_within_five_centimetres(vehicle, cruise_m_s):
    sc = _square(vehicle, cruise_m_s)
    limits = fcu_pipeline(sc)[0].commander.limits
    assert limits.cruise_speed_m_s == cruise_m_s and limits.vehicle == sc.vehicle
    plain = _legs(sc, dataclasses.replace(limits, vehicle=None))
    legs = _legs(sc, limits)
    assert plain == pytest.approx([1.875 * 2.0 / cruise_m_s + 1.0] * 4)  # travel + 1 s hold
    if cruise_m_s == 3.75:
        assert all(leg > plain[0] + 0.3 for leg in legs), legs  # the servos stretch them
    else:  # 2 s nearly fits: at most 1 % longer (the planar preset's y legs: 0.6 %)
        assert all(p <= leg < 1.01 * p for p, leg in zip(plain, legs, strict=True)), legs
    r = run_scenario(sc, logs=False)
    m = r.metrics
    assert m["status"] == "completed" and m["mission_completed"]
    assert m["position_error_m"]["max"] < 0.05
    assert m["attitude_error_rad"]["max"] < math.radians(3.0)
    assert not [e for e in r.events if "rate-limited" in e.text or "speed limit" in e.text]
    z = r.truth_col("pz")[:, 0]
    climbed = np.flatnonzero(z > 2.95)
    assert len(climbed) and z[climbed[0]:].min() > 2.9  # no ground contact after takeoff
