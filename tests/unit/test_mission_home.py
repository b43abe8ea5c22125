"""ArduPilot's home at mission seq 0 (gcs/vehicle_link/mission_home.py, the `gcs mission` commands):
a .plan, WPL or TOML file uploads to an ArduPilot-like vehicle with home at seq 0 and every
item after it, downloads back with home where the format keeps it and firmwareType 3;
to a PX4-like vehicle nothing changes; an item the vehicle refuses is exit 1 with its
reason."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from common.wire.mavlink import MAV, MAV_CMD_POSE_KEYFRAME
from common.wire.mission_items import HomePosition, MissionItem, local_xy, to_local
from gcs.mission_files import read_mission
from gcs.mission_files.plan import parse_plan_doc
from gcs.mission_files.toml import format_toml, parse_toml_doc
from gcs.mission_files.wpl import format_wpl, parse_wpl
from gcs.vehicle_link.mission_client import MissionError, upload_detailed
from gcs.vehicle_link.mission_home import HomeError, for_ardupilot, home_item, split_home, with_home
from tests.unit.scripted_autopilot import HOME, ScriptedAutopilot, gcs

M = MAV
pytestmark = pytest.mark.timeout(60)
DATA = Path(__file__).resolve().parents[1] / "data"
PLAN = DATA / "qgc_mission.plan"  # takeoff, 2 waypoints, loiter, land; home 47.397742...
NAN = math.nan
VEHICLE_HOME = HomePosition(*HOME)


def key(items):
    return [tuple("nan" if isinstance(v, float) and math.isnan(v) else v for v in it)
            for it in items]


def renumbered(items, start: int = 0):
    return [it._replace(seq=start + i) for i, it in enumerate(items)]


def jump(seq: int, target: int) -> MissionItem:
    return MissionItem(seq, 2, 177, 0, 1, float(target), 3.0, 0.0, 0.0, 0, 0, 0.0)


@pytest.fixture
def vehicles():
    made: list[ScriptedAutopilot] = []

    def make(kind: str, **kwargs) -> ScriptedAutopilot:
        v = ScriptedAutopilot(kind, **kwargs)
        made.append(v)
        return v

    yield make
    for v in made:
        v.close()




# ------------------------------------------------------------------ pure


def test_home_goes_first_and_jumps_follow():
    """Given items with a DO_JUMP to the second one, then with_home puts a home item (a
    NAV_WAYPOINT, MAV_FRAME_GLOBAL, AMSL) at seq 0, the items at 1..n and the jump's
    target one up; split_home gives both back exactly."""
    items = [*renumbered(read_mission(PLAN)), jump(5, 1)]
    wire = with_home(items, VEHICLE_HOME)
    assert wire[0] == home_item(VEHICLE_HOME)
    assert (wire[0].command, wire[0].frame, wire[0].x, wire[0].y, wire[0].z) == (
        16, 0, -353632621, 1491652374, 584.25)
    assert [it.seq for it in wire] == list(range(7))
    assert key(wire[1:6]) == key(renumbered(items[:5], 1))
    assert wire[6].param1 == 2.0  # the second item is seq 2 on the wire
    home, back = split_home(wire)
    assert home == VEHICLE_HOME and key(back) == key(items)


def test_for_ardupilot_takes_the_files_home_or_the_vehicles():
    """A plan's plannedHomePosition, TOML's [home], a WPL's home line 0 (sent as it is),
    else the vehicle's home; local items go in GLOBAL_RELATIVE_ALT; no home at all is a
    HomeError."""
    doc = parse_plan_doc(PLAN.read_text())
    planned = HomePosition(47.397742, 8.545594, 488.0)
    assert doc.home == planned
    wire = for_ardupilot(doc.items, "plan", doc.home, None)
    assert wire.home == planned and "plannedHomePosition" in wire.home_source
    assert len(wire.items) == 6 and key(wire.items[1:]) == key(renumbered(doc.items, 1))
    mavproxy = with_home(doc.items, VEHICLE_HOME)  # a WPL as MAVProxy saves it
    sent = for_ardupilot(parse_wpl(format_wpl(mavproxy)), "wpl", None, None)
    assert key(sent.items) == key(mavproxy) and sent.home_source == "the file's line 0"
    px4_wpl = for_ardupilot(parse_wpl(format_wpl(doc.items)), "wpl", None, VEHICLE_HOME)
    assert px4_wpl.home == VEHICLE_HOME and len(px4_wpl.items) == 6  # the takeoff kept
    assert px4_wpl.items[1].command == M.MAV_CMD_NAV_TAKEOFF
    local = [MissionItem(0, 1, 16, 1, 1, 0.0, 0.0, 0.0, NAN, local_xy(10.0), 0, -10.0)]
    toml = for_ardupilot(local, "toml", None, VEHICLE_HOME)
    assert toml.items[1].frame == M.MAV_FRAME_GLOBAL_RELATIVE_ALT and toml.items[1].z == 10.0
    assert to_local(toml.items[1], VEHICLE_HOME).x == pytest.approx(local_xy(10.0), abs=200)
    with pytest.raises(HomeError, match="no home"):
        for_ardupilot(doc.items, "plan", None, None)
    with pytest.raises(HomeError, match="local-frame"):
        for_ardupilot(local, "toml", None, None)


def test_toml_home_table_round_trip_and_checks():
    items = renumbered(read_mission(PLAN))
    text = format_toml(items, VEHICLE_HOME)
    assert "[home]" in text
    doc = parse_toml_doc(text)
    assert doc.home == VEHICLE_HOME and key(doc.items) == key(items)
    assert "[home]" not in format_toml(items)
    with pytest.raises(ValueError, match=r"\[home\]: unknown key 'alt'"):
        parse_toml_doc('[home]\nlat_deg = 1.0\nlon_deg = 2.0\nalt = 3.0\n')


# ------------------------------------------------------------------ through the CLI


def test_plan_upload_to_ardupilot_sends_home_then_every_item(vehicles, capsys, tmp_path):
    """Given an ArduPilot-like vehicle and QGC's 5-item plan, when it is uploaded, then the
    vehicle holds 6 items: the plan's plannedHomePosition at seq 0 and the 5 items at 1..5
    (the takeoff first); the download writes home back to plannedHomePosition (the vehicle's
    own, as ArduPilot answers seq 0), the 5 items and firmwareType 3."""
    v = vehicles("ardupilot")
    code, out, err = gcs(capsys, v, "mission", "upload", str(PLAN))
    assert code == 0, out + err
    assert "upload of 5 items: MAV_MISSION_ACCEPTED" in out
    assert "home (seq 0): lat 47.3977420, lon 8.5455940" in out
    items = read_mission(PLAN)
    assert len(v.mission) == 6
    assert v.mission[0] == home_item(HomePosition(47.397742, 8.545594, 488.0))
    assert key(v.mission[1:]) == key(renumbered(items, 1))
    back = tmp_path / "back.plan"
    code, out, err = gcs(capsys, v, "mission", "download", str(back))
    assert code == 0 and "downloaded 5 items" in out, out + err
    doc = json.loads(back.read_text())["mission"]
    assert doc["firmwareType"] == 3 and doc["plannedHomePosition"] == list(HOME)
    assert [e["command"] for e in doc["items"]] == [22, 16, 16, 19, 21]
    assert [e["doJumpId"] for e in doc["items"]] == [1, 2, 3, 4, 5]
    again = parse_plan_doc(back.read_text())
    assert key(again.items) == key(items) and again.home == VEHICLE_HOME


def test_plan_round_trip_through_ardupilot_is_the_same_plan(vehicles, capsys, tmp_path):
    """Given a plan whose planned home is the vehicle's home, when it goes up and comes
    back, then the plan read back is the same: items, home, firmwareType 3."""
    v = vehicles("ardupilot")
    src = tmp_path / "at_home.plan"
    doc = json.loads(PLAN.read_text())
    doc["mission"]["plannedHomePosition"] = list(HOME)
    doc["mission"]["firmwareType"] = 3
    src.write_text(json.dumps(doc))
    assert gcs(capsys, v, "mission", "upload", str(src))[0] == 0
    back = tmp_path / "back.plan"
    assert gcs(capsys, v, "mission", "download", str(back))[0] == 0
    mine, theirs = parse_plan_doc(src.read_text()), parse_plan_doc(back.read_text())
    assert key(mine.items) == key(theirs.items) and mine.home == theirs.home
    assert json.loads(back.read_text())["mission"]["firmwareType"] == 3


def test_wpl_and_toml_with_ardupilot(vehicles, capsys, tmp_path):
    """A WPL download from ArduPilot has home as line 0 and the items after it; uploaded
    again it goes as it is (no second home). A local TOML mission goes up after the vehicle's
    home in GLOBAL_RELATIVE_ALT (its takeoff and landing at lat = lon = 0, where the vehicle
    is) and downloads (--frame local) with [home] and the items."""
    v = vehicles("ardupilot")
    assert gcs(capsys, v, "mission", "upload", str(PLAN))[0] == 0
    wpl = tmp_path / "m.waypoints"
    assert gcs(capsys, v, "mission", "download", str(wpl))[0] == 0
    lines = parse_wpl(wpl.read_text())
    assert len(lines) == 6 and (lines[0].command, lines[0].frame) == (16, 0)
    assert split_home(lines)[0] == VEHICLE_HOME
    assert key(lines[1:]) == key(renumbered(read_mission(PLAN), 1))
    v.mission = []
    code, out, _ = gcs(capsys, v, "mission", "upload", str(wpl))
    assert code == 0 and "from the file's line 0" in out and len(v.mission) == 6
    assert key(v.mission[1:]) == key(lines[1:])
    local = [MissionItem(0, 1, 22, 1, 1, 0.0, 0.0, 0.0, NAN, 0, 0, -10.0),
             MissionItem(1, 1, 16, 0, 1, 0.0, 0.0, 0.0, NAN, local_xy(10.0), 0, -10.0),
             MissionItem(2, 1, 21, 0, 1, 0.0, 0.0, 0.0, NAN, 0, 0, 0.0)]
    src = tmp_path / "local.toml"
    src.write_text(format_toml(local))
    code, out, err = gcs(capsys, v, "mission", "upload", str(src))
    assert code == 0 and "upload of 3 items" in out, out + err
    assert "from the vehicle's HOME_POSITION" in out and len(v.mission) == 4
    assert [it.frame for it in v.mission[1:]] == [3, 3, 3]
    # the takeoff and the landing where the vehicle is (ArduPilot's lat = lon = 0): at
    # home's lat, lon ArduCopter's NAV_LAND would fly back home first
    assert [(it.x, it.y) for it in (v.mission[1], v.mission[3])] == [(0, 0), (0, 0)]
    assert (v.mission[2].x, v.mission[2].y) != (0, 0)
    back = tmp_path / "back.toml"
    assert gcs(capsys, v, "mission", "download", "--frame", "local", str(back))[0] == 0
    doc = parse_toml_doc(back.read_text())
    assert doc.home == VEHICLE_HOME and [it.command for it in doc.items] == [22, 16, 21]
    assert doc.items[1].x == pytest.approx(local_xy(10.0), abs=200)  # 2 cm: 1e-7 deg
    assert [it.z for it in doc.items] == pytest.approx([-10.0, -10.0, 0.0], abs=1e-3)


def test_refused_item_names_the_item_and_the_reason(vehicles, capsys, tmp_path):
    """Given an ArduPilot-like vehicle that refuses the keyframe command with no text
    (MAV_MISSION_UNSUPPORTED), then the upload is exit 1 naming the result and the item
    (the 4th of 4: seq 4); with a text, the text is the reason."""
    items = [*renumbered(read_mission(PLAN))[:3],
             MissionItem(3, 3, MAV_CMD_POSE_KEYFRAME, 0, 1, 1.0, 0.0, 0.0, 0.0,
                         473977420, 85455940, 5.0)]
    src = tmp_path / "key.waypoints"
    src.write_text(format_wpl(items))
    v = vehicles("ardupilot", refuse={MAV_CMD_POSE_KEYFRAME: (M.MAV_MISSION_UNSUPPORTED, "")})
    code, out, _ = gcs(capsys, v, "mission", "upload", str(src))
    assert code == 1
    assert "upload of 4 items refused: MAV_MISSION_UNSUPPORTED: item 4 of 4" in out, out
    said = vehicles("ardupilot", refuse={
        MAV_CMD_POSE_KEYFRAME: (M.MAV_MISSION_DENIED, "Mission: unknown command 31000")})
    code, out, _ = gcs(capsys, said, "mission", "upload", str(src))
    assert code == 1 and "MAV_MISSION_DENIED: Mission: unknown command 31000" in out, out


def test_no_home_anywhere_is_exit_1(vehicles, capsys, tmp_path):
    """A plan without plannedHomePosition to an ArduPilot-like vehicle that has no home yet
    is exit 1 with the reason, nothing uploaded; with a home the vehicle's is used."""
    doc = json.loads(PLAN.read_text())
    del doc["mission"]["plannedHomePosition"]
    src = tmp_path / "nohome.plan"
    src.write_text(json.dumps(doc))
    v = vehicles("ardupilot", home=None)
    code, _, err = gcs(capsys, v, "mission", "upload", str(src))
    assert code == 1 and "no home" in err and v.mission == []
    w = vehicles("ardupilot")
    code, out, _ = gcs(capsys, w, "mission", "upload", str(src))
    assert code == 0 and "from the vehicle's HOME_POSITION" in out
    assert w.mission[0] == home_item(VEHICLE_HOME) and len(w.mission) == 6


def test_px4_gets_the_items_as_they_are(vehicles, capsys, tmp_path):
    """To a PX4-like vehicle a plan goes without a home item (5 items from seq 0) and comes
    back with firmwareType 12; TOML downloads carry no [home]."""
    v = vehicles("px4")
    code, out, _ = gcs(capsys, v, "mission", "upload", str(PLAN))
    assert code == 0 and "home (seq 0)" not in out
    assert key(v.mission) == key(renumbered(read_mission(PLAN)))
    back = tmp_path / "back.plan"
    assert gcs(capsys, v, "mission", "download", str(back))[0] == 0
    mission = json.loads(back.read_text())["mission"]
    assert mission["firmwareType"] == 12 and len(mission["items"]) == 5
    toml = tmp_path / "back.toml"
    assert gcs(capsys, v, "mission", "download", str(toml))[0] == 0
    assert "[home]" not in toml.read_text()


def test_a_px4_mission_whose_first_item_reads_as_home_round_trips_through_wpl(
        vehicles, capsys, tmp_path):
    """A PX4 mission whose first item is a NAV_WAYPOINT at an AMSL position (what a WPL
    reader takes for a home line 0) downloads to WPL after the vehicle's home as line 0, and
    uploads back whole: the same items, none taken for home."""
    v = vehicles("px4")
    items = [MissionItem(0, 0, 16, 1, 1, 0.0, 0.0, 0.0, NAN, 473978000, 85456000, 500.0),
             MissionItem(1, 3, 16, 0, 1, 0.0, 0.0, 0.0, NAN, 473979000, 85456000, 10.0),
             MissionItem(2, 3, 21, 0, 1, 0.0, 0.0, 0.0, NAN, 0, 0, 0.0)]
    v.mission = list(items)
    wpl = tmp_path / "px4.waypoints"
    code, out, _ = gcs(capsys, v, "mission", "download", str(wpl))
    assert code == 0 and "after the vehicle's home as line 0" in out, out
    lines = parse_wpl(wpl.read_text())
    assert split_home(lines)[0] == VEHICLE_HOME and key(lines[1:]) == key(renumbered(items, 1))
    v.mission = []
    code, out, _ = gcs(capsys, v, "mission", "upload", str(wpl))
    assert code == 0 and "not sent" in out, out
    assert key(v.mission) == key(items)


def test_a_waypoint_yaw_uploaded_to_arducopter_is_said_to_be_ignored(vehicles, capsys,
                                                                      tmp_path):
    """ArduCopter keeps only a waypoint's delay (param1): an upload whose waypoints carry a
    yaw says that ArduCopter does not fly it, naming the items; none without a yaw."""
    v = vehicles("ardupilot")
    items = [MissionItem(0, 3, 22, 1, 1, 0.0, 0.0, 0.0, NAN, 0, 0, 10.0),
             MissionItem(1, 3, 16, 0, 1, 0.0, 0.0, 0.0, 90.0, 473978000, 85456000, 10.0),
             MissionItem(2, 3, 16, 0, 1, 0.0, 0.0, 0.0, NAN, 473979000, 85456000, 10.0)]
    wpl = tmp_path / "yaw.waypoints"
    wpl.write_text(format_wpl(items))
    code, out, _ = gcs(capsys, v, "mission", "upload", str(wpl))
    assert code == 0 and "ArduCopter does not fly a waypoint's yaw (param4): item 2 of 3" \
        in out, out
    wpl.write_text(format_wpl([it._replace(param4=NAN) for it in items]))
    code, out, _ = gcs(capsys, v, "mission", "upload", str(wpl))
    assert code == 0 and "yaw" not in out, out


def test_a_wpl_home_line_is_not_flown_by_px4(vehicles, capsys, tmp_path):
    """A QGC WPL 110 file whose line 0 is a home (MAVProxy's, Mission Planner's, ArduPilot's
    download: a NAV_WAYPOINT at home's AMSL altitude) goes to a PX4-like vehicle without it,
    as QGC reads such a file: sent as item 0, PX4 would fly to home at ground level first."""
    v = vehicles("px4")
    wpl = tmp_path / "mavproxy.waypoints"
    wpl.write_text(format_wpl(with_home(read_mission(PLAN), VEHICLE_HOME)))
    code, out, _ = gcs(capsys, v, "mission", "upload", str(wpl))
    assert code == 0 and "line 0 is a home" in out and "not sent" in out, out
    assert key(v.mission) == key(renumbered(read_mission(PLAN)))


def test_an_upload_never_asked_for_says_what_the_vehicle_said(vehicles):
    """Given a vehicle that answers MISSION_COUNT with a text and no MISSION_REQUEST, then
    the upload fails at its ceiling (the vehicle is heard all along) with what went unanswered
    and the vehicle's text."""
    from pymavlink import mavutil

    v = vehicles("ardupilot", mute="Mission: storage busy")
    conn = mavutil.mavlink_connection(v.url, source_system=255, source_component=190,
                                      dialect="common")
    try:
        with pytest.raises(MissionError, match=r"no answer to MISSION_COUNT\(2\) within "
                           r"the 0\.5 s ceiling .*; the vehicle said: Mission: storage busy"):
            upload_detailed(conn, 1, 1, with_home(read_mission(PLAN)[:1], VEHICLE_HOME),
                            timeout_s=0.2, ceiling_s=0.5)
    finally:
        conn.close()
