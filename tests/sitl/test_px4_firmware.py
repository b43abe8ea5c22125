"""The ground station and the plant against the real PX4 firmware (airframe 6011 on
`sitl --protocol px4-hil`, tests/px4_sitl.py), judged from the plant's truth log and PX4's
own ULogs: flights at PX4's default parameters, its height estimate against the truth,
IMU rates from 100 Hz to 1 kHz, a QGC mission through upload, download and flight (each
waypoint judged by PX4's own acceptance radius, NAV_ACC_RAD).

Skipped without $PX4_SITL (a px4_sitl_default build folder). The lockstep runs at twice
the wall clock (`--speed-factor 2`): PX4's timers run on simulated time, the ground
station's on the wall clock.
"""

from __future__ import annotations

import json
import re
import time
from pathlib import Path

import numpy as np
import pytest

from tests.px4_sitl import (
    Px4Run,
    logged_messages,
    needs_px4,
    parameter,
    px4_on_plant,
    sitl_stats,
    topic,
    truth,
)

pytestmark = [needs_px4, pytest.mark.process, pytest.mark.xdist_group("px4"),
              pytest.mark.timeout(1800)]

SPEED = ["--speed-factor", "2"]
PROFILE = Path(__file__).resolve().parents[2] / "config" / "sensors" / "px4-default.toml"
NAV_OFFBOARD, NAV_TAKEOFF, NAV_LOITER, NAV_RTL, NAV_LAND, NAV_MISSION = 14, 17, 4, 5, 18, 3
ARMED = 2
HOME_LAT, HOME_LON = 47.397742, 8.545594
# A sensor failure, an estimator reset or a battery failsafe said by PX4 (its console, its
# logged messages); not the SITL's own missing devices ("LED: open /dev/led0 failed").
SENSOR = r"(accel|gyro|baro|mag|gps|gnss|imu|sensor|height|hgt|ekf|estimator|battery)"
FAILURE = re.compile(rf"stale|{SENSOR}.*(fail|timeout|timed out|lost|reset|fault)|"
                     rf"(fail|timeout|reset|fault).*{SENSOR}|unhealthy|failsafe",
                     re.IGNORECASE)


def ok(done) -> str:
    assert done.returncode == 0, f"exit {done.returncode}\n{done.stdout}\n{done.stderr}"
    return done.stdout


def nav_windows(run: Px4Run, state: int) -> list[tuple[int, int]]:
    """(start, end) in us of each stretch PX4's vehicle_status.nav_state was `state`."""
    vs = topic(run.ulogs(), "vehicle_status")
    t, nav = vs["timestamp"], vs["nav_state"]
    out, start = [], None
    for i in range(len(t)):
        if nav[i] == state and start is None:
            start = int(t[i])
        elif nav[i] != state and start is not None:
            out.append((start, int(t[i])))
            start = None
    if start is not None:
        out.append((start, int(t[-1])))
    return out


def at(tr: dict, t_us: float) -> np.ndarray:
    """The truth (east, north, up) at t_us."""
    return np.array([np.interp(t_us, tr["timestamp"], tr[k]) for k in ("px", "py", "pz")])


def touchdowns(tr: dict) -> list[tuple[int, float]]:
    """(time us, vertical speed m/s) of each touchdown after flight: the vertical speed at
    the last instant above the ground (1 cm) before the plant's landed flag comes back."""
    landed = tr["landed"].astype(bool)
    above = tr["pz"] > 0.01
    out = []
    for i in np.nonzero(landed[1:] & ~landed[:-1])[0] + 1:
        before = np.nonzero(above[:i])[0]
        if len(before) == 0 or (tr["timestamp"][i] - tr["timestamp"][before[-1]]) > 5e6:
            continue  # no flight since the previous contact (a hop at spool-up)
        j = before[-1]
        if out and out[-1][0] >= tr["timestamp"][j]:
            continue  # a bounce of the same touchdown
        out.append((int(tr["timestamp"][j]), float(tr["vz"][j])))
    return out


def disarmed_at_end(run: Px4Run) -> bool:
    vs = topic(run.ulogs(), "vehicle_status")
    return int(vs["arming_state"][-1]) != ARMED


def failure_messages(run: Px4Run) -> list[str]:
    lines = [line for line in run.px4_log().splitlines() if FAILURE.search(line)]
    lines += [f"{t:.3f} {m}" for t, m in logged_messages(run.ulogs()) if FAILURE.search(m)]
    return lines


def height_errors(run: Px4Run, tr: dict) -> tuple[np.ndarray, np.ndarray]:
    """PX4's height estimate (vehicle_local_position -z) minus the truth's height at the
    same instants (both on the lockstep clock), and those instants (us), from the moment
    EKF2 first fuses its height reference (GNSS: estimator_status_flags.cs_gps_hgt) on:
    before that, in its first 1.5 s, it holds the height it started with."""
    lp = topic(run.ulogs(), "vehicle_local_position")
    flags = topic(run.ulogs(), "estimator_status_flags")
    fused = flags["timestamp"][flags["cs_gps_hgt"].astype(bool)]
    start = fused[0] if len(fused) else np.inf
    t = lp["timestamp"]
    keep = (t >= max(tr["timestamp"][0], start)) & (t <= tr["timestamp"][-1]) & \
        lp["z_valid"].astype(bool)
    t = t[keep]
    return -lp["z"][keep] - np.interp(t, tr["timestamp"], tr["pz"]), t


def land_and_wait(run: Px4Run) -> None:
    ok(run.gcs("mode", "LAND"))
    run.wait_disarmed()


@pytest.mark.timeout(1200)
def test_takeoff_goto_hold_rtl_lands_at_home(tmp_path: Path) -> None:
    with px4_on_plant(tmp_path, sitl_args=SPEED) as run:
        before = run.status()
        assert "readiness: ready to arm" in before, before
        assert re.search(r"mission: none\b", before), before
        ok(run.gcs("arm"))
        ok(run.gcs("takeoff", "--alt", "6"))
        ok(run.gcs("goto", "5", "0", "-6", "--tolerance", "0.5", "--tolerance-deg", "5"))
        ok(run.gcs("mode", "HOLD"))
        ok(run.gcs("mode", "RTL"))
        run.wait_disarmed()
    tr = truth(tmp_path)
    takeoff = nav_windows(run, NAV_TAKEOFF)
    assert takeoff, "PX4 never in AUTO_TAKEOFF"
    up = at(tr, takeoff[0][1])
    assert abs(up[2] - 6.0) <= 1.0 and np.hypot(up[0], up[1]) <= 1.0, up
    offboard = nav_windows(run, NAV_OFFBOARD)
    assert len(offboard) == 1, offboard
    start, end = offboard[0]
    inside = (tr["timestamp"] >= start) & (tr["timestamp"] <= end)
    assert tr["pz"][inside].min() >= 4.0, tr["pz"][inside].min()
    there = at(tr, end)
    assert np.linalg.norm(there - np.array([0.0, 5.0, 6.0])) <= 1.0, there
    assert nav_windows(run, NAV_RTL), "PX4 never in AUTO_RTL"
    contacts = touchdowns(tr)
    assert len(contacts) == 1, contacts
    assert abs(contacts[0][1]) < 1.0, contacts
    home = np.array([tr["px"][-1], tr["py"][-1]])
    assert np.hypot(*home) <= 1.0 and tr["landed"][-1], home
    assert disarmed_at_end(run)


@pytest.mark.timeout(1800)
def test_five_minutes_three_landings_height_within_20_cm(tmp_path: Path) -> None:
    """Three takeoffs to 6 m, 90 s hovers and landings (300 s and more of PX4's time) on the
    default noisy sensors (px4-default) at PX4's default parameters: no sensor-failure
    message; PX4's height estimate within 0.2 m of the truth throughout, the touchdowns
    included."""
    with px4_on_plant(tmp_path, sitl_args=SPEED) as run:
        for hover_s in (45.0, 45.0, 45.0):  # wall seconds: 90 s of simulated hover each
            ok(run.gcs("arm"))
            ok(run.gcs("takeoff", "--alt", "6"))
            time.sleep(hover_s)
            land_and_wait(run)
        failures = failure_messages(run)
        errors, t = height_errors(run, truth(tmp_path))
    tr = truth(tmp_path)
    assert tr["timestamp"][-1] - tr["timestamp"][0] >= 300e6, tr["timestamp"][-1]
    contacts = touchdowns(tr)
    assert len(contacts) == 3, contacts
    assert all(abs(vz) < 1.0 for _, vz in contacts), contacts
    assert not failures, "\n".join(failures)
    worst = int(np.argmax(np.abs(errors)))
    assert abs(errors[worst]) <= 0.2, (
        f"PX4's height estimate off the truth by {errors[worst]:+.3f} m at "
        f"t = {t[worst] * 1e-6:.1f} s (mean {errors.mean():+.3f} m, sd {errors.std():.3f} m)")


def profile_at(rate_hz: float, folder: Path) -> Path:
    """px4-default with only the IMU rate changed."""
    text = PROFILE.read_text()
    text, n = re.subn(r"(?m)^\[imu\]\nrate_hz = [0-9.]+", f"[imu]\nrate_hz = {rate_hz:.1f}",
                      text)
    assert n == 1
    text = text.replace('name = "px4-default"', f'name = "px4-imu-{rate_hz:g}"')
    path = folder / f"px4-imu-{rate_hz:g}.toml"
    path.write_text(text)
    return path


@pytest.mark.timeout(1200)
@pytest.mark.parametrize("rate_hz", [100.0, 250.0, 500.0, 1000.0])
def test_imu_rates_fly_without_stalls(tmp_path: Path, rate_hz: float) -> None:
    profile = profile_at(rate_hz, tmp_path)
    with px4_on_plant(tmp_path / "run", sitl_args=[*SPEED, "--sensors", str(profile)]) as run:
        ok(run.gcs("arm"))
        ok(run.gcs("takeoff", "--alt", "6"))
        time.sleep(10.0)
        ok(run.gcs("mode", "HOLD"))
        land_and_wait(run)
    stats = sitl_stats(tmp_path / "run")
    assert stats["imu_hz"] == rate_hz
    stalls = [float(m) for m in re.findall(r"no answer to the sample at t = ([0-9.]+) s",
                                           (tmp_path / "run" / "sitl.log").read_text())]
    # PX4's start-up (its first 0.3-0.6 s) answers every sample, then settles on its
    # rate-limited cadence: the plant steps past each answer that needs more samples
    # (grace_steps) and never waits out 1 s
    assert stalls == [] and stats["answer_waits"] == 0, (stalls, stats)
    tr = truth(tmp_path / "run")
    takeoff = nav_windows(run, NAV_TAKEOFF)
    assert takeoff
    up = at(tr, takeoff[0][1])
    assert abs(up[2] - 6.0) <= 1.0 and np.hypot(up[0], up[1]) <= 1.0, up
    contacts = touchdowns(tr)
    assert len(contacts) == 1 and abs(contacts[0][1]) < 1.0, contacts
    assert disarmed_at_end(run)


def plan(folder: Path) -> Path:
    """A QGC plan: takeoff to 5 m, two waypoints (frame 3, relative altitude), RTL."""
    def item(n: int, command: int, lat: float, lon: float, alt: float) -> dict:
        return {"AMSLAltAboveTerrain": None, "Altitude": alt, "AltitudeMode": 1,
                "autoContinue": True, "command": command, "doJumpId": n, "frame": 3,
                "params": [0, 0, 0, None, lat, lon, alt], "type": "SimpleItem"}
    north = 6.0 / 111_195.0  # 6 m in degrees of latitude
    east = 6.0 / (111_195.0 * np.cos(np.radians(HOME_LAT)))
    items = [item(1, 22, HOME_LAT, HOME_LON, 5.0),
             item(2, 16, HOME_LAT + north, HOME_LON, 5.0),
             item(3, 16, HOME_LAT + north, HOME_LON + east, 6.0),
             {**item(4, 20, 0.0, 0.0, 0.0), "frame": 2, "params": [0] * 7}]
    doc = {"fileType": "Plan", "version": 1, "groundStation": "QGroundControl",
           "geoFence": {"circles": [], "polygons": [], "version": 2},
           "rallyPoints": {"points": [], "version": 2},
           "mission": {"cruiseSpeed": 15, "firmwareType": 12, "globalPlanAltitudeMode": 1,
                       "hoverSpeed": 5, "items": items, "vehicleType": 2, "version": 2,
                       "plannedHomePosition": [HOME_LAT, HOME_LON, 488.0]}}
    path = folder / "mission.plan"
    path.write_text(json.dumps(doc, indent=2))
    return path


@pytest.mark.timeout(1200)
def test_qgc_plan_uploads_downloads_and_flies(tmp_path: Path) -> None:
    path = plan(tmp_path)
    back = tmp_path / "back.plan"
    with px4_on_plant(tmp_path / "run", sitl_args=SPEED) as run:
        ok(run.gcs("mission", "upload", str(path)))
        ok(run.gcs("mission", "download", str(back)))
        run.wait_ready()  # a mission checked, PX4's health checks run again
        ok(run.gcs("arm"))
        ok(run.gcs("mission", "start"))
        run.wait_disarmed(timeout=300)
    sent = json.loads(path.read_text())["mission"]["items"]
    got = json.loads(back.read_text())["mission"]["items"]
    assert [(i["command"], i["frame"]) for i in got] == \
        [(i["command"], i["frame"]) for i in sent], got
    for a, b in zip(sent, got, strict=True):
        for x, y in zip(a["params"][4:], b["params"][4:], strict=True):
            assert x is None or abs(x - y) < 1e-6, (a, b)
    tr = truth(tmp_path / "run")
    pts = np.stack([tr["px"], tr["py"], tr["pz"]], axis=1)
    # PX4 takes a multicopter's waypoint as reached within its acceptance radii, NAV_ACC_RAD
    # horizontally (a multicopter's default 2 m) and NAV_MC_ALT_RAD vertically (0.8 m), and
    # then turns to the next: judged by PX4's radii read from the ULog's parameters (with
    # 0.1 m for its estimate's error), not by a tighter one of ours.
    radius = parameter(run.ulogs(), "NAV_ACC_RAD") + 0.1
    alt_radius = parameter(run.ulogs(), "NAV_MC_ALT_RAD") + 0.1
    for target in ([0.0, 6.0, 5.0], [6.0, 6.0, 6.0]):
        near = (np.hypot(pts[:, 0] - target[0], pts[:, 1] - target[1]) <= radius) & \
            (np.abs(pts[:, 2] - target[2]) <= alt_radius)
        assert near.any(), (target, radius, alt_radius)
    assert nav_windows(run, NAV_MISSION)
    contacts = touchdowns(tr)
    assert len(contacts) == 1 and abs(contacts[0][1]) < 1.0, contacts
    assert np.hypot(tr["px"][-1], tr["py"][-1]) <= 1.0 and tr["landed"][-1]
    assert disarmed_at_end(run)
