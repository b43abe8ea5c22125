"""`gcs watch`'s view (gcs/cli/watch.py) from given messages: link lost, the active failsafe
with its reason, the landed state, health; `gcs status`'s formatting (gcs/vehicle_link/status.py):
no Python notation, sensible digits, JSON-ready values."""

from __future__ import annotations

import json
import math

from common.wire.mavlink import MAV as M
from gcs.cli.watch import ALERT, STALE_S, render, view_lines
from gcs.vehicle_link.snapshot import Snapshot
from gcs.vehicle_link.status import _shortest_f32, format_status

QUALITY = (0.0, 100, 0)


def _heartbeat(status: int = M.MAV_STATE_ACTIVE, armed: bool = True):
    base = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (M.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0)
    return M.MAVLink_heartbeat_message(M.MAV_TYPE_HEXAROTOR, M.MAV_AUTOPILOT_GENERIC, base,
                                       (4 << 16) | (3 << 24), status, 3)


def _snap(t0: float = 100.0, *messages) -> Snapshot:
    snap = Snapshot(started=t0)
    for msg in messages:
        snap.update(msg, now=t0)
    return snap


def test_a_live_vehicle_shows_landed_state_and_health():
    snap = _snap(100.0, _heartbeat(),
                 M.MAVLink_extended_sys_state_message(0, M.MAV_LANDED_STATE_IN_AIR),
                 M.MAVLink_sys_status_message(1, 1, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0),
                 M.MAVLink_local_position_ned_message(1000, 1.0, 2.0, -3.0, 0, 0, 0))
    lines = view_lines(1, snap, 100.5, QUALITY)
    text = "\n".join(t for t, _ in lines)
    assert "mode HOLD" in text and "ARMED" in text and "in air" in text
    assert "health        ok" in text and "LINK LOST" not in text and "FAILSAFE" not in text
    assert all(style != "stale" for _, style in lines)


def test_link_lost_after_two_seconds_marks_values_stale():
    snap = _snap(100.0, _heartbeat(),
                 M.MAVLink_local_position_ned_message(1000, 1.0, 2.0, -3.0, 0, 0, 0))
    assert "LINK LOST" not in "\n".join(render(1, snap, 100.0 + STALE_S - 0.1, QUALITY))
    lines = view_lines(1, snap, 105.2, QUALITY)
    assert lines[1] == ("LINK LOST for 5 s: no HEARTBEAT; the values below are the last "
                        "heard", ALERT)
    plain = render(1, snap, 105.2, QUALITY)
    position = next(line for line in plain if line.startswith("position NED"))
    assert position.endswith("[stale]")
    assert not plain[1].endswith("[stale]")  # the alarm itself is current


def test_active_failsafe_shows_the_last_failsafe_text():
    snap = _snap(100.0, _heartbeat(),
                 M.MAVLink_statustext_message(M.MAV_SEVERITY_CRITICAL,
                                              b"state input lost: disarming", 0, 0),
                 M.MAVLink_statustext_message(M.MAV_SEVERITY_INFO, b"disarmed", 0, 0),
                 _heartbeat(M.MAV_STATE_CRITICAL, armed=False))
    lines = view_lines(1, snap, 100.1, QUALITY)
    assert ("FAILSAFE (CRITICAL): state input lost: disarming", ALERT) in lines
    snap.update(_heartbeat(M.MAV_STATE_EMERGENCY, armed=False), now=100.2)
    assert ("FAILSAFE (EMERGENCY): state input lost: disarming", ALERT) in \
        view_lines(1, snap, 100.3, QUALITY)
    snap.update(_heartbeat(M.MAV_STATE_STANDBY, armed=False), now=100.4)
    assert not any("FAILSAFE" in t for t, _ in view_lines(1, snap, 100.5, QUALITY))


def test_unhealthy_sensors_are_named():
    gyro, accel = M.MAV_SYS_STATUS_SENSOR_3D_GYRO, M.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    snap = _snap(100.0, _heartbeat(),
                 M.MAVLink_sys_status_message(gyro | accel, gyro | accel, gyro, 0, 0, 0, 0, 0,
                                              0, 0, 0, 0, 0))
    text = "\n".join(render(1, snap, 100.1, QUALITY))
    assert "health        unhealthy: 3D_ACCEL" in text


def test_waiting_before_the_first_heartbeat():
    assert render(3, Snapshot(started=0.0), 1.0, QUALITY)[1] == "waiting for HEARTBEAT ..."


def test_float32_values_in_their_shortest_form():
    f32 = M.MAVLink_local_position_ned_message(0, 0.1, -2.25, 1e-7, 0, 0, 0)
    raw = f32.pack(M.MAVLink(None))
    packed = M.MAVLink(None).decode(bytearray(raw))
    assert packed.x != 0.1  # float32: 0.10000000149011612
    assert _shortest_f32(packed.x) == 0.1 and _shortest_f32(packed.y) == -2.25 \
        and _shortest_f32(packed.z) == 1e-7
    assert _shortest_f32(-0.0) == 0.0 and math.copysign(1, _shortest_f32(-0.0)) == 1.0
    assert _shortest_f32(math.nan) is None and _shortest_f32(math.inf) is None


def test_status_lines_have_units_and_no_python_notation():
    status = {"system": 1, "component": 1, "type": "MAV_TYPE_HEXAROTOR", "mode": "HOLD",
              "armed": False, "position_ned_m": [0.1, -2.25, -0.0],
              "roll_pitch_yaw_deg": [20.004, -0.5, 60.0], "q_ned_frd": [1.0, 0.0, 0.0, 0.0],
              "capabilities": ["MISSION_INT", "MAVLINK2"],
              "global": {"lat_deg": 47.397742, "lon_deg": 8.545594, "alt_m": 488.0,
                         "relative_alt_m": 0.0},
              "mission": {"current": 1, "total": 5, "state": "MISSION_STATE_ACTIVE"},
              "link": {"loss_percent": 0.5, "received": 199, "lost": 1},
              "messages": ["armed", "mode HOLD"]}
    lines = format_status(status)
    text = "\n".join(lines)
    for python in ("[", "]", "{", "}", "'", "True", "False", "None"):
        assert python not in text
    assert "            system: 1 (component 1)" in lines
    assert "             armed: no" in lines
    assert "    position_ned_m: 0.100, -2.250, 0.000 m" in lines
    assert "roll_pitch_yaw_deg: 20.00, -0.50, 60.00 deg" in lines
    assert "      capabilities: MISSION_INT, MAVLINK2" in lines
    assert "           mission: item 1 of 5, MISSION_STATE_ACTIVE" in lines
    assert "              link: 0.50 % lost (1 of 200 messages)" in lines
    assert lines[-2:] == ["           message: armed", "           message: mode HOLD"]
    json.dumps(status, allow_nan=False)
