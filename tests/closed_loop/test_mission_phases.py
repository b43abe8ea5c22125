"""Every phase of a mission flies within the envelope, on both vehicle files: a take-off to a
low height (on planar rotors the climb's braking must not reverse the thrust), and a landing
at any accepted land speed through contact until the disarm (the touchdown must not push the
rotors' thrust to reverse on the ground). Judged from the plant's truth: the tilt servos'
rates, the touchdown speed, the status and the FCU's actuator monitor."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from common.config.scenario import load_vehicle
from gcs.run.inprocess import InProcessError, run_scenario

from .conftest import ROOT, scenario

VEHICLES = ["hexa_tilted", "hexa_planar"]


def _mission(folder: Path, takeoff_m: float, middle: str) -> Path:
    path = folder / "phases.toml"
    path.write_text(f"""format = "dqflight-mission-1"
[[item]]
type = "takeoff"
altitude_ned_z_m = {-takeoff_m}
climb_time_s = 0.0
yaw_deg = nan
[[item]]
{middle}
[[item]]
type = "land"
yaw_deg = nan
""")
    return path


def _hold(takeoff_m: float) -> str:
    return (f'type = "waypoint"\nposition_ned_m = [0.0, 0.0, {-takeoff_m}]\nhold_s = 1.0\n'
            'yaw_deg = nan')


def _scenario(folder: Path, vehicle: str, takeoff_m: float, land_m_s: float,
              duration_s: float, middle: str | None = None,
              start_enu_m: tuple[float, float, float] = (0.0, 0.0, 0.0)):
    sc = scenario("mission_square", duration_s=duration_s,
                  vehicle=load_vehicle(ROOT / "config" / "vehicles" / f"{vehicle}.toml"))
    path = _mission(folder, takeoff_m, middle or _hold(takeoff_m))
    return dataclasses.replace(
        sc, trajectory=dataclasses.replace(sc.trajectory, mission_file=str(path)),
        params={"MIS_LAND_SPD": land_m_s}, initial_position_enu_m=start_enu_m)  # the
    # other speeds the parameters' defaults, not the square's


def _fly(folder: Path, vehicle: str, takeoff_m: float, land_m_s: float, duration_s: float):
    sc = _scenario(folder, vehicle, takeoff_m, land_m_s, duration_s)
    return sc, run_scenario(sc, logs=False)


def _judge(sc, r) -> dict:
    """The flight's figures from truth: fastest servo, touchdown speeds, disarmed."""
    m = r.metrics
    t = r.truth_col("time_us")[:, 0] * 1e-6
    tilts = r.truth_col(*(f"tilt{i}" for i in range(6)))
    rates = np.abs(np.diff(tilts, axis=0)) / np.diff(t)[:, None]
    vz, landed = r.truth_col("vz", "landed").T
    contacts = [float(vz[k - 1]) for k in range(1, len(t)) if landed[k] > 0.5 > landed[k - 1]]
    disarm = [e["t_s"] for e in m["events"] if e["text"] == "landed: disarmed"]
    return {"status": m["status"], "servo_rad_s": float(rates.max()), "contacts": contacts,
            "disarm": disarm,
            "limits": [e["text"] for e in m["events"] if e.get("kind") == "limit"]}


@pytest.mark.parametrize("vehicle", VEHICLES)
@pytest.mark.parametrize("takeoff_m", [0.3, 0.5])
def test_a_low_takeoff_flies_and_lands(tmp_path, vehicle, takeoff_m):
    """Given a take-off to 0.3 or 0.5 m at the default take-off speed (before, on the planar
    preset the climb braked beyond g: every servo rate-limited at 30-50 rad/s and a crash at
    4.5 m/s), then the climb is stretched to what the rotors brake without reversing, and the
    mission flies: completed, no actuator limit, servos within their rate, one touchdown
    under 1 m/s, disarmed."""
    sc, r = _fly(tmp_path, vehicle, takeoff_m, 0.5, 10.0)
    f = _judge(sc, r)
    assert f["status"] == "completed" and not f["limits"], f
    assert f["servo_rad_s"] <= sc.vehicle.tilt_rate_max_rad_s * 0.999, f
    assert f["contacts"] and all(abs(v) < 1.0 for v in f["contacts"]), f
    assert len(f["disarm"]) == 1, f
    assert r.truth_col("pz")[:, 0].max() == pytest.approx(takeoff_m, abs=0.02)


@pytest.mark.parametrize("vehicle", VEHICLES)
@pytest.mark.parametrize("land_m_s", [0.5, 1.0, 3.0])
def test_every_land_speed_lands_without_a_limited_servo(tmp_path, vehicle, land_m_s):
    """Given a landing from 2 m at 0.5, 1 or 3 m/s (before: from 0.89 m/s on, the sinking
    set-point flipped every servo on the ground; at 3 m/s a crash at 11.7 m/s), then the
    descent flies at the land speed, the touchdown at the speed the gains land at, and the
    vehicle lands and disarms with every servo within its rate, through contact to disarm."""
    sc, r = _fly(tmp_path, vehicle, 2.0, land_m_s, 14.0)
    f = _judge(sc, r)
    assert f["status"] == "completed" and not f["limits"], f
    assert f["servo_rad_s"] <= sc.vehicle.tilt_rate_max_rad_s * 0.999, f
    assert f["contacts"] and all(abs(v) < 0.7 for v in f["contacts"]), f
    assert len(f["disarm"]) == 1, f
    capped = [e for e in r.metrics["events"] if e["text"].startswith("touchdown capped")]
    # said when the mission is taken (before the flight) and again at the touchdown
    assert len(capped) == (2 if land_m_s > 0.59 else 0), capped
    if capped:
        assert capped[0]["t_s"] == 0.0 and capped[1]["t_s"] > 3.0, capped


KEYFRAME_HOME = ('type = "keyframe"\ntime_s = 1.0\nposition_ned_m = [0.0, 0.0, -2.0]\n'
                 "rotvec_ned_frd_rad = [0.0, 0.0, 0.0]")


@pytest.mark.parametrize("vehicle", VEHICLES)
def test_a_start_away_from_home_is_checked_from_there(tmp_path, vehicle):
    """Given a take-off to 2 m and a 1 s keyframe to 2 m above home (accepted at upload: from
    home it does not move), when the vehicle starts 3 m from home, then MISSION_START is
    refused with the item, the actuator and the duration that would pass, and nothing is
    flown (status aborted, not completed with limit warnings); from home it flies."""
    sc = _scenario(tmp_path, vehicle, 2.0, 0.5, 12.0, KEYFRAME_HOME, (3.0, 0.0, 0.0))
    with pytest.raises(InProcessError) as refused:
        run_scenario(sc, logs=False)
    text = str(refused.value)
    assert "mission refused from here: MAV_MISSION_DENIED: item 1: tilt servo" in text
    assert "lengthen p1 to" in text
    assert refused.value.result is not None
    assert refused.value.result.metrics["status"] == "aborted"
    home = _scenario(tmp_path, vehicle, 2.0, 0.5, 12.0, KEYFRAME_HOME)
    r = run_scenario(home, logs=False)
    assert r.metrics["status"] == "completed"


def _plan_with_speeds(folder: Path) -> Path:
    """tests/data/qgc_mission.plan's take-off (3 m at home) and a 2 m leg north and back,
    each after a DO_CHANGE_SPEED as QGC writes it (command 178, frame 2, params [1 (ground
    speed), speed, -1 (throttle), 0, 0, 0, 0]), then RTL's home landing as NAV_LAND."""
    doc = json.loads((ROOT / "tests" / "data" / "qgc_mission.plan").read_text())
    takeoff = doc["mission"]["items"][0]
    north = 2.0 / 111_320.0  # deg of latitude in 2 m

    def waypoint(n: int, lat: float) -> dict:
        return {**takeoff, "command": 16, "doJumpId": n,
                "params": [0, 0, 0, None, lat, takeoff["params"][5], 3]}

    def speed(n: int, m_s: float) -> dict:
        return {"autoContinue": True, "command": 178, "doJumpId": n, "frame": 2,
                "params": [1, m_s, -1, 0, 0, 0, 0], "type": "SimpleItem"}

    lat0 = takeoff["params"][4]
    land = {**takeoff, "command": 21, "doJumpId": 6, "Altitude": 0,
            "params": [0, 0, 0, None, lat0, takeoff["params"][5], 0]}
    doc["mission"]["items"] = [takeoff, speed(2, 0.5), waypoint(3, lat0 + north),
                               speed(4, 1.0), waypoint(5, lat0), land]
    path = folder / "speeds.plan"
    path.write_text(json.dumps(doc, indent=4))
    return path


@pytest.mark.parametrize("vehicle", VEHICLES)
def test_a_plan_with_speed_changes_flies_its_legs_at_those_speeds(tmp_path, vehicle):
    """Given a QGC plan whose 2 m legs follow DO_CHANGE_SPEED 0.5 and 1 m/s, then each leg
    peaks at its speed and no faster (a leg lasts 1.875 x distance / speed: 7.5 and 3.75 s,
    both within the envelope), the mission completes, and the speed items cost no time.
    (Before, a speed was a leg's mean: it peaked at 0.94 and 1.88 m/s.)"""
    sc = scenario("mission_square", duration_s=24.0,
                  vehicle=load_vehicle(ROOT / "config" / "vehicles" / f"{vehicle}.toml"))
    sc = dataclasses.replace(sc, trajectory=dataclasses.replace(
        sc.trajectory, mission_file=str(_plan_with_speeds(tmp_path))))
    r = run_scenario(sc, logs=False)
    assert r.metrics["status"] == "completed", r.metrics["events"]
    t = r.truth_col("time_us")[:, 0] * 1e-6
    py, vx, vy = r.truth_col("py", "vx", "vy").T
    speed = np.hypot(vx, vy)
    out = (py > 0.05) & (py < 1.95) & (vy > 0.0)
    back = (py > 0.05) & (py < 1.95) & (vy < 0.0)
    assert speed[out].max() == pytest.approx(0.5, rel=0.03)
    assert speed[back].max() == pytest.approx(1.0, rel=0.03)
    assert t[out][-1] - t[out][0] > 2.0 * (t[back][-1] - t[back][0]) * 0.9
