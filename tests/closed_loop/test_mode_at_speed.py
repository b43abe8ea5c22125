"""LAND, RTL and a new current item asked while a fast mission is under way start their
plans where HOLD's brake brings the reference to rest
(`fcu.modes.mode_state.ModeState._after_brake`, `brake_then`): through the in-process
plant, the vehicle follows its reference within centimetres, no actuator saturates, and
LAND lands. Started at once from rest, their plans stepped the reference's velocity to
zero: 5-7.5 m off the reference and the rotors saturated for seconds."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from common.wire.modes import Mode
from gcs.run.inprocess import run_scenario

from .conftest import scenario

DO_CHANGE_SPEED = 178


def _fast_mission(folder: Path, speed_m_s: float) -> Path:
    """Up 10 m, then 80 m north at `speed_m_s` (DO_CHANGE_SPEED)."""
    path = folder / "fast.toml"
    path.write_text(f"""format = "dqflight-mission-1"
[[item]]
type = "takeoff"
altitude_ned_z_m = -10.0
climb_time_s = 0.0
yaw_deg = nan
[[item]]
type = "raw"
command = {DO_CHANGE_SPEED}
frame = 1
autocontinue = 1
params = [1.0, {speed_m_s}, -1.0, 0.0]
x = 0
y = 0
z = 0.0
[[item]]
type = "waypoint"
position_ned_m = [80.0, 0.0, -10.0]
hold_s = 1.0
yaw_deg = nan
""")
    return path


@pytest.mark.parametrize(("mode", "speed_m_s", "at_s", "duration_s"),
                         [(Mode.LAND, 9.375, 15.0, 40.0), (Mode.RTL, 15.0, 13.0, 40.0),
                          (Mode.MISSION, 15.0, 13.0, 30.0)])
def test_land_and_rtl_at_speed_brake_first_and_fly_within_centimetres(
        tmp_path, mode, speed_m_s, at_s, duration_s):
    """Given a mission flying north at 7-11 m/s, still speeding up, when LAND, RTL or a new
    current item (MISSION: its last, the waypoint) comes (at a fixed simulated time), then
    the reference brakes from that speed (its velocity continuous) and its plan flies on
    from where it stopped: the vehicle stays within 5 cm of the reference, no actuator
    saturates or rate-limits, LAND disarms on the ground and the mission completes."""
    sc = scenario("mission_square", duration_s=duration_s)
    sc = dataclasses.replace(sc, trajectory=dataclasses.replace(
        sc.trajectory, mission_file=str(_fast_mission(tmp_path, speed_m_s))))
    seen: dict[str, object] = {}

    def before_step(t_us: int, pipeline) -> None:
        c = pipeline.commander
        start = seen.setdefault("start_us", t_us)
        if "entry" not in seen and t_us - start >= at_s * 1e6:
            seen["entry"] = c.last_ref
            seen["answer"] = (c.set_mission_current(2) if mode == Mode.MISSION else
                              c.set_mode(mode, 0.0)).result
        elif "entry" in seen and "after" not in seen:
            seen["after"] = c.last_ref

    m = run_scenario(sc, logs=False, before_step=before_step).metrics
    entry, after = seen["entry"], seen["after"]
    assert seen["answer"] == (5 if mode == Mode.MISSION else 0)  # IN_PROGRESS: braking
    speed = sum(v * v for v in entry.v_enu_m_s) ** 0.5
    assert speed > 6.5 and entry.a_enu_m_s2[1] > 1.0  # at speed, still speeding up
    dv = [abs(a - b) for a, b in zip(after.v_enu_m_s, entry.v_enu_m_s, strict=True)]
    assert max(dv) < 0.02  # one 2 ms step of braking, no step to rest
    assert m["saturated_steps"] == 0
    assert m["position_error_m"]["max"] < 0.05
    assert [e for e in m["events"] if e.get("kind") == "limit"] == []
    texts = [e["text"] for e in m["events"]]
    assert "landed: disarmed" in texts if mode == Mode.LAND else \
        "mission complete" in texts if mode == Mode.MISSION else True
