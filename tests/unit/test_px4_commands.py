"""`gcs goto`, `takeoff`, `mode` and `status` against a scripted PX4 (tests/px4_gcs_side.py)
that takes SET_ATTITUDE_TARGET as PX4 does: the CLI flies PX4 with the position and yaw
alone, refuses a roll or a pitch, and a falling vehicle ends the command at once with
UNSAFE (goto: the stream stops and HOLD is commanded). Through the real `gcs` entry point
and Session over loopback UDP."""

from __future__ import annotations

import json
import math
import socket
import time

import pytest

from gcs.cli import main
from gcs.vehicle_link.descent import DescentWatch, Unsafe
from tests.px4_gcs_side import LOITER, OFFBOARD, ScriptedPX4Vehicle


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture
def px4():
    port = _free_udp_port()
    made: list[ScriptedPX4Vehicle] = []

    def start(**kwargs) -> tuple[ScriptedPX4Vehicle, list[str]]:
        vehicle = ScriptedPX4Vehicle(port, **kwargs)
        made.append(vehicle)
        return vehicle, ["--connect", f"udpin:127.0.0.1:{port}"]

    yield start
    for vehicle in made:
        vehicle.close()


def test_goto_flies_px4_with_the_position_and_yaw_alone(px4, capsys):
    vehicle, link = px4(airborne_m=6.0)
    t0 = time.monotonic()
    code = main(["goto", "5", "0", "-6", "--yaw", "30", "--timeout", "20",
                 "--tolerance", "0.1", "--tolerance-deg", "2", *link])
    out = capsys.readouterr()
    assert code == 0, out.err
    assert "reached: position error" in out.out
    assert vehicle.got.count("SET_ATTITUDE_TARGET") == 0  # PX4 would drop position control
    assert vehicle.got.count("SET_POSITION_TARGET_LOCAL_NED", after=t0) > 10
    assert OFFBOARD in vehicle.got.modes
    assert math.dist(vehicle.p, (5.0, 0.0, -6.0)) < 0.15
    assert vehicle.yaw == pytest.approx(math.radians(30.0), abs=math.radians(3.0))


def test_a_station_that_sends_attitude_targets_to_px4_sees_it_fall_and_holds(px4):
    """What `gcs goto` did before: position and attitude targets to PX4. The scripted PX4
    drops position control (thrust 0 with ignore-throttle); goto must end at once with
    UNSAFE, stop streaming and command HOLD."""
    from gcs.vehicle_link.goto import goto
    from gcs.vehicle_link.pose import PoseTarget
    from gcs.vehicle_link.session import Session

    vehicle, link = px4(airborne_m=6.0)
    session = Session(link[1])
    try:
        session.wait_vehicle(timeout=5.0)
        target = PoseTarget.from_euler_deg((5.0, 0.0, -6.0), 0.0, 0.0, 0.0)
        t0 = time.monotonic()
        with pytest.raises(Unsafe, match=r"^UNSAFE: .*m/s.*commanded HOLD: confirmed"):
            goto(session, target, arm_first=False, tolerance_m=0.05, tolerance_rad=0.02,
                 timeout=30.0, hold_s=0.0, full_pose=True)
        ended = time.monotonic()
        assert ended - t0 < 8.0  # at once, not at the timeout
        assert vehicle.got.count("SET_ATTITUDE_TARGET") > 0
        assert vehicle.mode == LOITER
        time.sleep(0.3)
        assert vehicle.got.count("SET_POSITION_TARGET_LOCAL_NED", after=ended + 0.1) == 0
        assert -vehicle.p[2] > 1.0  # caught before the ground
    finally:
        session.close()


@pytest.mark.parametrize("axis", ["--roll", "--pitch"])
def test_a_roll_or_pitch_on_px4_is_refused_before_anything_is_sent(px4, capsys, axis):
    vehicle, link = px4(airborne_m=6.0)
    code = main(["goto", "5", "0", "-6", axis, "10", "--timeout", "5", *link])
    err = capsys.readouterr().err
    assert code == 2
    assert "--roll and --pitch must be 0 on PX4" in err
    assert vehicle.got.count("SET_POSITION_TARGET_LOCAL_NED") == 0
    assert OFFBOARD not in vehicle.got.modes


def test_goto_on_a_disarmed_vehicle_without_arm_is_refused_at_once(px4, capsys):
    vehicle, link = px4()
    t0 = time.monotonic()
    code = main(["goto", "0", "0", "-3", "--timeout", "30", *link])
    assert code == 1
    assert "disarmed: arm it first or give --arm" in capsys.readouterr().err
    assert time.monotonic() - t0 < 10.0
    assert OFFBOARD not in vehicle.got.modes


def test_takeoff_that_loses_its_thrust_is_unsafe(px4, capsys):
    vehicle, link = px4()
    vehicle.cut_thrust_below_m = 3.0  # the motors stop once 3 m up
    assert main(["arm", *link]) == 0
    t0 = time.monotonic()
    code = main(["takeoff", "--alt", "6", "--timeout", "30", *link])
    err = capsys.readouterr().err
    assert code == 1
    assert "UNSAFE: " in err and "m/s" in err
    assert time.monotonic() - t0 < 15.0


def test_mode_hold_on_a_falling_vehicle_is_unsafe(px4, capsys):
    vehicle, link = px4(airborne_m=40.0)
    vehicle.motors_dead = True  # falling when the station asks for HOLD
    deadline = time.monotonic() + 5.0
    while vehicle.v[2] < 3.0 and time.monotonic() < deadline:
        time.sleep(0.02)
    code = main(["mode", "HOLD", "--wait", "5", *link])
    assert code == 1
    assert "UNSAFE: " in capsys.readouterr().err


def test_takeoff_and_goto_on_px4_arrive(px4, capsys):
    vehicle, link = px4()
    assert main(["arm", *link]) == 0
    assert main(["takeoff", "--alt", "6", "--timeout", "30", *link]) == 0
    assert -vehicle.p[2] == pytest.approx(6.0, abs=0.6)
    assert main(["goto", "5", "0", "-6", "--timeout", "20", "--tolerance", "0.1",
                 "--tolerance-deg", "2", *link]) == 0
    assert main(["mode", "HOLD", *link]) == 0
    assert vehicle.mode == LOITER
    assert vehicle.got.count("SET_ATTITUDE_TARGET") == 0
    capsys.readouterr()


@pytest.mark.parametrize("raises", [False, True])
def test_a_takeoff_below_mis_takeoff_alt(px4, capsys, raises):
    """`takeoff --alt 1` sends home + 1 m whatever MIS_TAKEOFF_ALT (2.5 m) is: PX4 1.15 and
    later take the altitude as given, and it is reached at 1 m. PX4 up to 1.14 raised it to
    MIS_TAKEOFF_ALT and said so after its answer ("Using minimum takeoff altitude: 2.50 m"):
    then `gcs` says so too and waits for 2.5 m, rather than calling 0.5 m reached while the
    vehicle climbs on."""
    vehicle, link = px4(raises_takeoff=raises)
    assert main(["arm", *link]) == 0
    capsys.readouterr()
    assert main(["takeoff", "--alt", "1", "--timeout", "30", *link]) == 0
    out = capsys.readouterr().out
    assert vehicle.takeoff_asked_m == pytest.approx(1.0, abs=1e-3)  # p7 AMSL, float32
    reached = float(out.split("reached: ")[1].split(" m")[0])
    if raises:
        assert "the vehicle raised the takeoff to 2.5 m above home" in out, out
        assert reached >= 2.0 and vehicle.takeoff_z == pytest.approx(-2.5)
    else:
        assert "raised" not in out and 0.5 <= reached < 1.5, out
        assert vehicle.takeoff_z == pytest.approx(-1.0)


def test_status_on_px4_reads_readiness_from_health_and_no_mission(px4, capsys):
    _vehicle, link = px4()
    assert main(["status", "--json", *link]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["readiness"]["ready_to_arm"] is True
    assert out["mission"]["total"] == 0
    assert main(["status", *link]) == 0
    text = capsys.readouterr().out
    assert "readiness: ready to arm" in text
    assert "mission: none" in text


# ------------------------------------------------------------------ the watch itself


def _watch(**kwargs) -> DescentWatch:
    return DescentWatch(1.0, "MPC_Z_VEL_MAX_DN", **kwargs)


def test_a_descent_within_the_limit_passes_and_a_fall_does_not():
    w = _watch()
    for i in range(100):  # 2 m/s for 1 s: within 1.5 x 1 + 0.5
        w.sample(10.0 - 0.02 * i * 2.0, -2.0, i * 0.01)
    w = _watch()
    w.sample(10.0, -2.1, 0.0)
    w.sample(9.9, -2.2, 0.1)
    with pytest.raises(Unsafe, match=r"descending at 2\.30 m/s"):
        w.sample(9.8, -2.3, 0.2)  # 0.2 s beyond the threshold


def test_a_short_dip_past_the_speed_is_not_a_fall():
    w = _watch()
    w.sample(10.0, -2.5, 0.0)
    w.sample(9.9, -1.0, 0.15)  # back within the limit
    w.sample(9.8, -2.5, 0.2)
    w.sample(9.7, -2.5, 0.35)  # only 0.15 s since it exceeded again


def test_the_floors():
    w = _watch(floor_from_start=True, floor_cap_m=6.0)  # goto from 8 m to 6 m
    w.sample(8.0, 0.0, 0.0)
    w.sample(5.1, -1.0, 1.0)  # 0.9 m under the target's height: still flying there
    with pytest.raises(Unsafe, match=r"lost 1\.1\d m of height uncommanded"):
        w.sample(4.9, -1.0, 1.1)
    w = _watch(rising_floor=True)  # takeoff: the highest point reached
    for i, h in enumerate((0.0, 2.0, 4.0, 3.5)):
        w.sample(h, 0.0, i * 0.1)
    with pytest.raises(Unsafe):
        w.sample(2.9, -0.5, 1.0)
    w = _watch()  # no floor: LAND descends by design
    w.sample(10.0, -1.0, 0.0)
    w.sample(0.0, -1.0, 10.0)


def test_mode_offboard_on_px4_is_refused_before_anything_is_sent(px4, capsys):
    """`gcs mode OFFBOARD` streams no set-points: PX4 takes OFFBOARD on the ground without
    them and then outputs nothing (in lockstep its clock stops), so the CLI says so, exit 2,
    and sends no DO_SET_MODE; `gcs goto` is the way."""
    vehicle, link = px4()
    assert main(["mode", "OFFBOARD", *link]) == 2
    assert "use gcs goto" in capsys.readouterr().err
    assert OFFBOARD not in vehicle.got.modes
    assert vehicle.got.count("COMMAND_LONG") <= 2  # AUTOPILOT_VERSION asked, nothing else


def test_goto_judges_its_floor_in_its_targets_frame(px4, capsys):
    """The local origin 3 m below home (ArduPilot sets it at its first fix), the vehicle
    sending GLOBAL_POSITION_INT before each LOCAL_POSITION_NED: goto from 6 m down to 4.5 m
    above the origin (1.5 m above home) arrives. Its floor is capped by the target's local
    height, so the heights it watches are the local ones: judged on the height above home,
    the floor of 3 m (6 m local) would be crossed 1.5 m below, an UNSAFE that never was."""
    vehicle, link = px4(airborne_m=6.0, origin_below_home_m=3.0)
    code = main(["goto", "0", "0", "-4.5", "--timeout", "20", "--tolerance", "0.1", *link])
    out = capsys.readouterr()
    assert code == 0, out.out + out.err
    assert "UNSAFE" not in out.out + out.err and "reached: position error" in out.out
    assert vehicle.p[2] == pytest.approx(-4.5, abs=0.15)


def test_the_sustain_is_judged_on_the_vehicles_clock():
    """Messages that arrive together are as far apart as their time_boot_ms says: 0.1 s of
    the vehicle's flight past the limit is no fall, whatever the receiving clock; 0.3 s is."""
    from pymavlink.dialects.v20 import common

    def pos(ms: int, z: float, vz: float):
        return common.MAVLink_local_position_ned_message(ms, 0.0, 0.0, z, 0.0, 0.0, vz)

    w = _watch()
    w.update(pos(1000, -10.0, 2.5), 50.0)
    w.update(pos(1100, -9.75, 2.5), 50.0)  # received at the same instant: 0.1 s apart
    w.update(pos(1150, -9.6, 2.5), 99.0)  # received 49 s later: still 0.15 s of flight
    with pytest.raises(Unsafe, match=r"for 0\.30 s"):
        w.update(pos(1300, -9.25, 2.5), 99.0)
