"""The actuator monitor in flight (COM_ACT_RATE_T): a mission beyond the tilt servos' rate is
reported, naming the servos that lag in the plant; Case I has no such report."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from gcs.run.inprocess import run_scenario
from gcs.run.runio import RunResult

from .. import reference_runs
from .conftest import scenario

LIMIT_S = 0.1  # COM_ACT_RATE_T's default

# A takeoff to 3 m in 3 s, then one 2 m leg in 1 s (MIS_TKO_SPD 1.875 and MIS_CRUISE_SPD 3.75
# m/s, top speeds) flown as timed: its start needs more tilt rate than the servos have (with
# the envelope check off).
FAST = {"MIS_TKO_SPD": 1.875, "MIS_CRUISE_SPD": 3.75}
LEG = """format = "dqflight-mission-1"

[[item]]
type = "takeoff"
altitude_ned_z_m = -3.0
climb_time_s = 0.0
yaw_deg = nan

[[item]]
type = "waypoint"
position_ned_m = [2.0, 0.0, -3.0]
hold_s = 2.0
yaw_deg = nan
"""


def _fly_leg(tmp_path: Path, **params: float) -> RunResult:
    path = tmp_path / "leg.toml"
    path.write_text(LEG)
    sc = scenario("mission_tour", duration_s=8.0)
    sc = dataclasses.replace(sc, trajectory=dataclasses.replace(sc.trajectory,
                                                                mission_file=str(path)),
                             params={"MIS_ENV_CHK": 0.0, **FAST, **params})
    return run_scenario(sc, logs=False)


def _lagging_servos(r: RunResult, rate_max_rad_s: float, limit_s: float) -> dict[int, float]:
    """From the plant's truth, not the FCU's model: servo (0-based) -> the first instant it
    has been unable to reach its command in every period for longer than limit_s."""
    t_us = r.onboard_col("time_us")[:, 0].astype(np.int64)
    cmd = r.onboard_col(*(f"tilt_cmd{i}" for i in range(6)))
    rows = np.searchsorted(r.truth_col("time_us")[:, 0], t_us)
    tilt = r.truth_col(*(f"tilt{i}" for i in range(6)))[rows]
    dt_s = float(np.median(np.diff(t_us))) * 1e-6
    lag = np.abs(cmd - tilt) > rate_max_rad_s * dt_s + 1e-4
    out = {}
    for i in range(6):
        run = 0
        for k in range(len(t_us)):
            run = run + 1 if lag[k, i] else 0
            if run * dt_s > limit_s + 1e-9:
                out[i] = t_us[k] * 1e-6
                break
    return out


def test_a_leg_beyond_the_tilt_rate_is_reported_naming_the_servos(tmp_path):
    """Given a 2 m leg in 1 s with the envelope check off, when flown in-process, then
    metrics' events carry a WARNING "tilt servo N rate-limited" for exactly the servos whose
    plant tilt lagged its command for longer than COM_ACT_RATE_T, each within a period of
    when the truth shows it, at a rate above the limit; "actuator limits cleared" (INFO)
    follows; the reports are not failsafes but limits (kind "limit"): the run that reached
    its end is "limited", its reason the first report."""
    r = _fly_leg(tmp_path)
    m = r.metrics
    events = m["events"]
    warned: dict[int, float] = {}
    for e in events:
        if " rate-limited " in e["text"]:
            assert e["text"].startswith("tilt servo ") and e["severity"] == 4
            assert e["kind"] == "limit"
            servo = int(e["text"].split()[2]) - 1
            warned.setdefault(servo, e["t_s"])
            demanded = float(e["text"].split(": ")[1].split(" > ")[0])
            assert demanded > 4.0
    assert warned, events
    truth = _lagging_servos(r, scenario("mission_tour").vehicle.tilt_rate_max_rad_s, LIMIT_S)
    assert set(warned) == set(truth)
    for servo, t_s in warned.items():
        assert abs(t_s - truth[servo]) <= 0.0041  # two periods: the FCU judges ahead
    first = min(warned.values())
    cleared = [e for e in events if e["text"] == "actuator limits cleared"]
    assert cleared and cleared[0]["t_s"] > first and cleared[0]["severity"] == 6
    assert cleared[0]["kind"] == "info"
    assert m["status"] == "limited", m["status_reason"]
    first_report = min((e for e in events if e["kind"] == "limit"), key=lambda e: e["t_s"])
    assert m["status_reason"].startswith(
        f"actuator limit at t = {first_report['t_s']:.3f} s: {first_report['text']}")


def test_the_parameter_sets_the_time_in_flight(tmp_path):
    """Given the same leg with COM_ACT_RATE_T = 0.3 s, then each servo is first reported when
    the plant's truth shows it lagging for longer than 0.3 s (within two periods), at least
    0.2 s later than the default's time would."""
    r = _fly_leg(tmp_path, COM_ACT_RATE_T=0.3)
    warned: dict[int, float] = {}
    for e in r.metrics["events"]:
        if " rate-limited " in e["text"]:
            assert " rate-limited 0.3 s: " in e["text"]
            warned.setdefault(int(e["text"].split()[2]) - 1, e["t_s"])
    rate_max = scenario("mission_tour").vehicle.tilt_rate_max_rad_s
    truth, default = _lagging_servos(r, rate_max, 0.3), _lagging_servos(r, rate_max, LIMIT_S)
    assert warned and set(warned) == set(truth)
    for servo, t_s in warned.items():
        assert abs(t_s - truth[servo]) <= 0.0041
        assert t_s >= default[servo] + 0.2 - 1e-6


def test_divergence_still_ends_the_run_diverged(tmp_path):
    """Given the leg with COM_DIV_POS = 0.3 m, then the tilt servos are reported and the run
    ends "diverged" by the divergence rule, as without the monitor."""
    m = _fly_leg(tmp_path, COM_DIV_POS=0.3).metrics
    texts = [e["text"] for e in m["events"]]
    assert any(" rate-limited " in t for t in texts)
    assert m["status"] == "diverged" and "failsafe: diverged (0.3 m)" in texts


@pytest.mark.xdist_group(reference_runs.GROUP)
def test_case1_has_no_actuator_report():
    """Given Case I (160 s, default actuators), then no actuator is reported: 0 false
    alarms."""
    m = reference_runs.case1_metrics()
    assert m["status"] == "completed"
    texts = [e["text"] for e in m["events"]]
    assert not [t for t in texts if "rate-limited" in t or "speed limit" in t
                or t == "actuator limits cleared"], texts
