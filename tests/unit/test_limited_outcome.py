"""An honest outcome: the actuator monitor's reports make a run `limited` (common/outcome.py,
fcu/pipeline.py), the errors are judged over the rows the vehicle is meant to follow
(gcs/report/metrics.py `followed_rows`), and a campaign's summary counts limited runs apart."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from common.config.scenario import load_gains, load_scenario, load_vehicle
from common.logs.columns import ONBOARD_COLUMNS, TRUTH_COLUMNS
from common.outcome import LIMIT, classify
from common.wire.modes import Mode
from fcu.edge.setpoint_wire import position_target
from fcu.pipeline import Pipeline
from fcu.safety.failsafe import FailsafeSettings
from fcu.stages import VehicleState
from gcs.campaign.load import load_campaign
from gcs.campaign.report import write_report
from gcs.report.metrics import ERROR_ROWS_RULE, build_metrics, followed_rows

ROOT = Path(__file__).resolve().parents[2]


def test_rotor_limits_are_limit_events_and_the_run_is_limited():
    """Given an offboard target 30 m away and a vehicle that does not move (the rotors
    saturate), COM_SAT_T 0.2 s, when the pipeline steps for 4 s, then the monitor's "rotor N
    at speed limit" and the saturation report are WARNINGs of kind LIMIT (no reaction), and
    a run with those events that reached its end is limited; without them it would be
    completed."""
    vehicle = load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml")
    pipe = Pipeline(vehicle, load_gains(ROOT / "config/gains/pid_eq30.toml"), 500,
                    failsafes=FailsafeSettings(saturation_s=0.2, divergence_m=1000.0))
    still = VehicleState((1.0, 2.0, 5.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                         (0.0, 0.0, 0.0))
    pipe.on_state(0, still, 0)
    assert pipe.arm()[0] == 0
    c = pipe.commander
    assert c.offboard_position(0.0, position_target(1, 0, (30.0, 0.0, -5.0), (0.0, 0.0, 0.0),
                               (0.0, 0.0, 0.0), 0.0))[0]
    assert c.set_mode(Mode.OFFBOARD, 0.0)[0] == 0
    for t in range(0, 4_000_000, 2000):
        pipe.on_state(t, still, t)
        pipe.step(t, 0.002)
    rotor = [e for e in pipe.events if " at speed limit " in e.text]
    saturated = [e for e in pipe.events if e.text.startswith("rotors saturated")]
    assert rotor and saturated
    assert all(e.kind == LIMIT and e.severity == 4 for e in rotor + saturated)
    out = classify(reached_end=True, events=pipe.events, divergence_t_us=None)
    first = next(e for e in pipe.events if e.kind == LIMIT)
    assert out.status == "limited" and out.reason.startswith(
        f"actuator limit at t = {first.t_us * 1e-6:.3f} s: {first.text}")
    others = [e for e in pipe.events if e.kind != LIMIT]
    assert classify(reached_end=True, events=others, divergence_t_us=None).status == \
        "completed"


def _ground_logs() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Truth and onboard logs at 500 Hz of a short flight, level attitude throughout:
    0-0.5 s on the ground, the reference climbing from z = 0 (1 mm behind: counted);
    0.5-3 s in the air 2 mm off the reference; 3-3.2 s in the air just above the ground
    with the reference 5 mm below it (counted: in the air); 3.2-4 s on the ground, the
    reference sinking to 0.4 m below it (left out)."""
    t = np.arange(0.0, 4.0 + 1e-9, 0.002)
    truth = np.zeros((len(t), len(TRUTH_COLUMNS)))
    onboard = np.zeros((len(t), len(ONBOARD_COLUMNS)))
    for log, columns in ((truth, TRUTH_COLUMNS), (onboard, ONBOARD_COLUMNS)):
        log[:, columns.index("time_us")] = np.round(t * 1e6)
    truth[:, TRUTH_COLUMNS.index("qw")] = 1.0
    onboard[:, ONBOARD_COLUMNS.index("qdw")] = 1.0
    onboard[:, ONBOARD_COLUMNS.index("armed")] = 1.0
    z_d = np.where(t < 0.5, 0.01 * t, 1.0)
    z = np.where(t < 0.5, np.maximum(z_d - 0.001, 0.0), 0.998)
    air_low = (t >= 3.0) & (t < 3.2)
    z_d[air_low], z[air_low] = -0.005, 0.001
    sink = t >= 3.2
    z_d[sink], z[sink] = -0.001 - 0.5 * (t[sink] - 3.2), 0.0
    landed = (t < 0.5) & (z <= 0.0) | sink
    truth[:, TRUTH_COLUMNS.index("pz")] = z
    truth[:, TRUTH_COLUMNS.index("landed")] = landed
    onboard[:, ONBOARD_COLUMNS.index("pdz")] = z_d
    return t, truth, onboard


def test_errors_leave_out_the_ground_below_the_reference_only():
    """Given the logs above, then the errors are those of the rows in the air and of the
    climb from the ground: the 6 mm in the air at 3-3.2 s is the maximum, the sinking
    set-point on the ground (up to 0.4 m) is not counted; error_rows says which rows."""
    t, truth, onboard = _ground_logs()
    sc = dataclasses.replace(load_scenario(ROOT / "config/scenarios/mission_tour.toml"),
                             duration_s=4.0)
    m = build_metrics(sc, TRUTH_COLUMNS, truth, ONBOARD_COLUMNS, onboard, events=[],
                      wall_time_s=1.0, transport="in-process", lockstep=True)
    sink = int(np.sum(t >= 3.2))
    assert m["error_rows"] == {"rule": ERROR_ROWS_RULE, "counted": len(t) - sink,
                               "on_ground_reference_below": sink}
    assert m["samples"] == len(t)  # the joined rows, as before
    err = np.abs(truth[:, TRUTH_COLUMNS.index("pz")] - onboard[:, ONBOARD_COLUMNS.index("pdz")])
    kept = err[t < 3.2]
    assert m["position_error_m"]["max"] == pytest.approx(0.006)
    assert m["position_error_m"]["mean"] == pytest.approx(float(np.mean(kept)))
    assert m["position_error_m"]["rmse"] == pytest.approx(float(np.sqrt(np.mean(kept ** 2))))
    assert m["status"] == "completed"


def test_the_rule_row_by_row():
    """On the ground with the reference below it: left out; on the ground with the reference
    at or above it, or in the air whatever the reference: counted."""
    p_d = np.array([[0, 0, -0.1], [0, 0, 0.0], [0, 0, 0.2], [0, 0, -0.1], [0, 0, np.nan]])
    landed = np.array([1.0, 1.0, 1.0, 0.0, 1.0])
    assert followed_rows(p_d, landed).tolist() == [False, True, True, True, True]
    assert followed_rows(np.zeros((0, 3)), np.zeros(0)).tolist() == []


def test_campaign_summary_counts_limited_runs_apart(tmp_path):
    """Given four runs, one limited, then the summary's success is 2/4 (limited is not a
    success) and a line counts the limited run."""
    campaign = load_campaign(ROOT / "config/campaigns/smoke.toml")
    rows = [{"controller": c, "disturbance.force[0].magnitude": 10.0,
             "disturbance.force[0].azimuth_deg": 0.0, "status": s, "sim_time_s": 3.0,
             "position_error_m.max": 0.01, "attitude_error_rad.max": 0.001}
            for c, s in (("pid", "completed"), ("pid", "limited"), ("pd", "completed"),
                         ("pd", "diverged"))]
    text = write_report(tmp_path, campaign, rows).read_text()
    assert "Success (status completed): 2/4 = 50.0 %" in text
    assert "limited 1" in text
    assert "Limited (flown to the end with an actuator at its limit, not a success): 1/4" \
        in text
