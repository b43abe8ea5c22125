"""The 2 m square at up to 4 m/s (config/scenarios/mission_square.toml) through the real
processes: the vehicle accepts it, stretches its legs to what every actuator can follow, and
flies it within millimetres with no ground contact, in lockstep and in real time. Its legs
in 1 s once asked the tilt servos for 13 rad/s (limit 4) and put the vehicle on the ground."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from common.config.scenario import load_scenario
from common.logs.columns import ONBOARD_COLUMNS, TRUTH_COLUMNS
from fcu.edge.onboard_log import DQ_ONBOARD_COLUMNS

from .conftest import ROOT, SCENARIOS
from .test_estimator_flight import read_topic

pytestmark = pytest.mark.timeout(240)
SQUARE = SCENARIOS / "mission_square.toml"


@pytest.mark.parametrize("clock", ["lockstep", "realtime"])
def test_square_at_four_metres_per_second_is_stretched_and_flown(tmp_path, clock):
    out = tmp_path / "run"
    argv = [sys.executable, "-m", "gcs.cli", "run", str(SQUARE), "--out", str(out)]
    proc = subprocess.run([*argv, *(["--realtime"] if clock == "realtime" else [])],
                          cwd=ROOT, capture_output=True, text=True, timeout=200, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    m = json.loads((out / "metrics.json").read_text())
    assert m["status"] == "completed" and m["mission_completed"], m["status_reason"]
    assert m["position_error_m"]["max"] < 0.05
    assert m["attitude_error_rad"]["max"] < math.radians(3.0)
    assert m["saturated_steps"] == 0
    texts = [e["text"] for e in m["events"]]
    assert not [t for t in texts if "rate-limited" in t or "speed limit" in t], texts
    # No ground contact between the end of the takeoff and the end of the last leg: the
    # truth stays near 3 m up and the commanded tilts never outrun the servos' rate.
    cols, truth = read_topic(out / "truth.ulg", "dq_truth")
    assert tuple(cols) == TRUTH_COLUMNS
    z = truth[:, TRUTH_COLUMNS.index("pz")]
    t_s = (truth[:, 0] - truth[0, 0]) * 1e-6
    climbed = np.flatnonzero(z > 2.95)
    assert len(climbed), "never reached 3 m"
    after = slice(climbed[0], None)
    assert z[after].min() > 2.9 and not truth[after, TRUTH_COLUMNS.index("landed")].any()
    assert t_s[-1] > 15.0  # stretched: 2.8 s takeoff + 4 x (0.94 s + 1 s) would end by 11 s
    ocols, onboard = read_topic(out / "onboard.ulg", "dq_onboard")
    assert tuple(ocols) == DQ_ONBOARD_COLUMNS
    airborne = onboard[onboard[:, 0] >= truth[climbed[0], 0]]
    tilt = airborne[:, [ONBOARD_COLUMNS.index(f"tilt_cmd{i}") for i in range(6)]]
    # Sustained rates: over every window of 50 control steps, as the monitor judges. A row's
    # stamp is that of the state its step acted on: in real time, on a busy machine, the
    # plant's process can be starved and several steps act on one state (one stamp), so a
    # window lasted the longer of its stamps' span and its steps' (more than 49 periods: a
    # step starts no earlier than its period is due, and the next is due after it starts).
    scenario = load_scenario(SQUARE)
    period_s = 1.0 / scenario.control_rate_hz
    span_s = np.maximum((airborne[50:, 0] - airborne[:-50, 0]) * 1e-6, 49 * period_s)
    rate = np.abs(tilt[50:] - tilt[:-50]).max(axis=1) / span_s
    vehicle = scenario.vehicle
    assert 0.5 < rate.max() <= vehicle.tilt_rate_max_rad_s, rate.max()
