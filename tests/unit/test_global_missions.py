"""Missions in global frames: the geodetic <-> local conversion (common/geodetic.py), items
converted through the home (common/wire/mission_items.py), the vehicle's acceptance of global
items and its refusal of local items that MAVProxy scaled by 1e7 (fcu/mission/,
fcu/edge/mission_protocol.py)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from common.config.scenario import load_vehicle
from common.geodetic import EARTH_RADIUS_M, geodetic_to_ned, ned_to_geodetic
from common.wire.mavlink import MAV, MAV_CMD_FIGURE_EIGHT, MAV_CMD_POSE_KEYFRAME
from common.wire.mission_items import (
    GEO_FRAMES,
    HomePosition,
    MissionItem,
    item_from_message,
    local_xy,
    to_global,
    to_local,
)
from common.wire.mission_messages import item_message
from fcu.edge.mission_protocol import MissionServer
from fcu.mission.limits import MissionLimits
from fcu.mission.validation import check_mission, localize
from gcs.mission_files.wpl import format_wpl

from ..closed_loop.conftest import ROOT

M = MAV
HOME = HomePosition(47.397742, 8.545594, 488.0)  # the FCU's default --home
VEHICLE = (1, 1)
GCS = (255, 0)  # MAVProxy's source system and component
WP = M.MAV_CMD_NAV_WAYPOINT

# MISSION_ITEM_INT carries latitude in 1e-7 deg: a step is 1.11 cm north, 0.75 cm east here;
# rounding to it moves a point by at most half a step each way.
HALF_STEP_M = math.hypot(0.5e-7 * math.pi / 180 * EARTH_RADIUS_M,
                         0.5e-7 * math.pi / 180 * EARTH_RADIUS_M *
                         math.cos(math.radians(HOME.lat_deg)))

metres = st.floats(-5000.0, 5000.0, allow_nan=False)
lat = st.floats(-80.0, 80.0, allow_nan=False)


def _local(seq: int, command: int, north: float = 0.0, east: float = 0.0, z: float = 0.0,
           p1: float = 0.0, p4: float = math.nan) -> MissionItem:
    return MissionItem(seq, M.MAV_FRAME_LOCAL_NED, command, int(seq == 0), 1, p1, 0.0, 0.0,
                       p4, local_xy(north), local_xy(east), z)


def _mission() -> list[MissionItem]:
    return [_local(0, M.MAV_CMD_NAV_TAKEOFF, z=-3.0),
            _local(1, WP, 2.345, -1.234, -3.0, p1=2.0),
            _local(2, M.MAV_CMD_NAV_LOITER_TIME, -1.5, 2.25, -4.0, p1=3.0),
            MissionItem(3, M.MAV_FRAME_LOCAL_NED, MAV_CMD_POSE_KEYFRAME, 0, 1, 6.0, 0.125,
                        -0.25, 0.5, local_xy(0.5), local_xy(0.75), -3.5),
            MissionItem(4, M.MAV_FRAME_LOCAL_NED, MAV_CMD_FIGURE_EIGHT, 0, 1, 1.0, 120.0, 2.0,
                        1.0, 0, 0, -3.0),
            _local(5, M.MAV_CMD_NAV_LAND)]


# ------------------------------------------------------------------ the conversion


@settings(max_examples=300, deadline=None)
@given(metres, metres, metres, lat, st.floats(-179.0, 179.0), st.floats(-400.0, 9000.0))
def test_geodetic_is_the_exact_inverse_of_ned_both_ways(n, e, d, home_lat, home_lon, home_alt):
    """Given a local point within 5 km of any home, then local -> geodetic -> local and
    geodetic -> local -> geodetic agree to far below 1 mm (float rounding: nanometres)."""
    lat_deg, lon_deg, alt = ned_to_geodetic((n, e, d), home_lat, home_lon, home_alt)
    back = geodetic_to_ned(lat_deg, lon_deg, alt, home_lat, home_lon, home_alt)
    assert math.dist(back, (n, e, d)) < 1e-6
    again = ned_to_geodetic(back, home_lat, home_lon, home_alt)
    north_m = math.radians(again[0] - lat_deg) * EARTH_RADIUS_M
    east_m = math.radians(again[1] - lon_deg) * EARTH_RADIUS_M * math.cos(
        math.radians(home_lat))
    assert math.hypot(north_m, east_m) < 1e-6 and abs(again[2] - alt) < 1e-6


def test_geodetic_conversion_scale():
    """Given the home, then 1e-7 deg of latitude is 1.11 cm north and the home is the origin."""
    assert geodetic_to_ned(HOME.lat_deg, HOME.lon_deg, HOME.alt_m, *HOME) == (0.0, 0.0, 0.0)
    n, e, d = geodetic_to_ned(HOME.lat_deg + 1e-7, HOME.lon_deg, HOME.alt_m + 2.0, *HOME)
    assert n == pytest.approx(0.0111319, abs=1e-7) and e == 0.0 and d == -2.0


@settings(max_examples=300, deadline=None)
@given(st.sampled_from([WP, M.MAV_CMD_NAV_LOITER_TIME, MAV_CMD_POSE_KEYFRAME]),
       st.floats(-900.0, 900.0), st.floats(-900.0, 900.0), st.floats(-100.0, 100.0),
       st.sampled_from(sorted(GEO_FRAMES)))
def test_items_go_global_and_back_within_the_wire_step(command, n, e, z, frame):
    """Given a local position item, when converted to a global frame and back, then its
    position moves by at most half of MISSION_ITEM_INT's 1e-7 deg step (the only loss) and
    its altitude not at all (above home or AMSL)."""
    item = MissionItem(0, M.MAV_FRAME_LOCAL_NED, command, 1, 1, 1.0, 0.0, 0.0, 0.0,
                       local_xy(n), local_xy(e), z)
    glob = to_global(item, HOME, frame)
    assert glob.frame == frame and glob.xy_fit_int32
    amsl = frame in (M.MAV_FRAME_GLOBAL, M.MAV_FRAME_GLOBAL_INT)
    assert glob.z == pytest.approx(HOME.alt_m - z if amsl else -z, abs=1e-9)
    back = to_local(glob, HOME)
    assert back.frame == M.MAV_FRAME_LOCAL_NED
    assert math.hypot(back.x_m - item.x_m, back.y_m - item.y_m) <= HALF_STEP_M + 1e-4
    assert back.z == pytest.approx(z, abs=1e-9)


def test_unused_slots_and_other_commands():
    """Takeoff and land keep their altitude, not their unused x, y; the figure's z is an
    axis component and stays; a command without positions keeps its frame."""
    takeoff = to_global(_local(0, M.MAV_CMD_NAV_TAKEOFF, 1.0, 1.0, z=-3.0), HOME)
    assert (takeoff.frame, takeoff.z) == (M.MAV_FRAME_GLOBAL_RELATIVE_ALT, 3.0)
    assert to_local(takeoff, HOME)[9:12] == (0, 0, -3.0)
    figure = _mission()[4]
    assert to_global(figure, HOME).z == -3.0 and to_local(to_global(figure, HOME), HOME).z == -3.0
    servo = _local(0, M.MAV_CMD_DO_SET_SERVO)._replace(frame=M.MAV_FRAME_GLOBAL_INT)
    assert to_local(servo, HOME) is servo
    with pytest.raises(ValueError, match="not a global frame"):
        to_global(_mission()[1], HOME, M.MAV_FRAME_GLOBAL_TERRAIN_ALT)


def test_home_as_home_position_carries_it():
    """The vehicle converts through its home as HOME_POSITION publishes it (1e-7 deg, mm),
    so the ground station's conversions use the same numbers."""
    home = HomePosition.published(47.39774213, 8.54559449, 488.1234)
    msg = M.MAVLink_home_position_message(473977421, 85455945, 488123, 0.0, 0.0, 0.0,
                                          [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0)
    assert HomePosition.from_message(msg) == home == (47.3977421, 8.5455945, 488.123)


# ------------------------------------------------------------------ the vehicle's checks

LIMITS = MissionLimits()


def test_global_mission_is_accepted_and_flown_as_its_local_equivalent():
    """Given a mission in GLOBAL_RELATIVE_ALT (and the same in GLOBAL_INT, AMSL), then the
    vehicle accepts it with its home and flies the local items; without a home, or in a
    terrain frame, it is MAV_MISSION_UNSUPPORTED_FRAME."""
    local = _mission()
    for frame in (M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                  M.MAV_FRAME_GLOBAL, M.MAV_FRAME_GLOBAL_INT):
        glob = [to_global(it, HOME, frame) for it in local]
        assert check_mission(glob, LIMITS, HOME).result == M.MAV_MISSION_ACCEPTED
        flown = localize(glob, HOME)
        assert all(it.frame == M.MAV_FRAME_LOCAL_NED for it in flown)
        for a, b in zip(flown, local, strict=True):
            assert math.hypot(a.x_m - b.x_m, a.y_m - b.y_m) <= HALF_STEP_M + 1e-4
            assert a.z == pytest.approx(b.z, abs=1e-9)
        assert check_mission(glob, LIMITS).result == M.MAV_MISSION_UNSUPPORTED_FRAME
    terrain = [it._replace(frame=M.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT)
               for it in (to_global(it, HOME) for it in local)]
    assert check_mission(terrain, LIMITS, HOME).result == M.MAV_MISSION_UNSUPPORTED_FRAME


def test_global_items_out_of_range_or_far_away():
    """A latitude beyond 90 deg is INVALID_PARAM5_X, a longitude beyond 180 INVALID_PARAM6_Y,
    a waypoint 1.1 km away (or 2000 km) is DENIED with the geofence's reason."""
    wp = to_global(_mission()[1], HOME)._replace(seq=0)
    check = check_mission([wp._replace(x=900_000_001)], LIMITS, HOME)
    assert check.result == M.MAV_MISSION_INVALID_PARAM5_X
    check = check_mission([wp._replace(y=-1_800_000_001)], LIMITS, HOME)
    assert check.result == M.MAV_MISSION_INVALID_PARAM6_Y
    for dlat_e7, km in ((100_000, 1), (200_000_000, 2226)):
        check = check_mission([wp._replace(x=wp.x + dlat_e7)], LIMITS, HOME)
        assert check.result == M.MAV_MISSION_DENIED and check.seq == 0
        assert "beyond the geofence" in check.reason and f"{km}" in check.reason


def _through_mavproxy(text: str, tmp_path) -> list[MissionItem]:
    """A WPL file as MAVProxy's `wp load` sends it: pymavlink's loader, then MAVProxy's own
    MISSION_ITEM -> MISSION_ITEM_INT conversion (x, y times 1e7, truncated). Imported here,
    after common.wire.mavlink has chosen MAVLink 2 for pymavlink's mavutil."""
    from MAVProxy.modules.lib.mission_item_protocol import MissionItemProtocolModule
    from pymavlink import mavwp

    path = tmp_path / "mission.waypoints"
    path.write_text(text)
    loader = mavwp.MAVWPLoader()
    loader.load(str(path))

    class Module:  # the two methods of MAVProxy's wp module that the conversion uses
        has_location = MissionItemProtocolModule.has_location
        to_int = MissionItemProtocolModule.wp_to_mission_item_int

    return [item_from_message(Module().to_int(loader.wp(i))) for i in range(loader.count())]


def test_mavproxy_scaled_local_file_is_refused_with_the_reason(tmp_path):
    """Given a local-frame WPL file as the README used to describe it, when MAVProxy loads it
    (x, y scaled by 1e7: 2.345 m arrives as 2345 m), then the vehicle refuses it with
    MAV_MISSION_DENIED and a reason that names the scaling and the remedy."""
    sent = _through_mavproxy(format_wpl(_mission()), tmp_path)
    assert sent[1].x == int(2.345 * 1e7)
    check = check_mission(sent, LIMITS, HOME)
    assert check.result == M.MAV_MISSION_DENIED and check.seq == 1
    assert check.reason == ("item 1: x 2345 m, y -1234 m, beyond the geofence (1000 m): a "
                            "local WPL file scaled by 1e7 (MAVProxy)? use a global frame")
    # a vertical reach beyond the fence keeps the geofence's own reason
    high = check_mission([_local(0, WP, z=-2000.0)], LIMITS, HOME)
    assert high.result == M.MAV_MISSION_DENIED and "scaled" not in high.reason


def test_mavproxy_global_file_arrives_as_written(tmp_path):
    """Given the mission written in GLOBAL_RELATIVE_ALT, when MAVProxy loads the file (it
    truncates x * 1e7), then every item arrives with the integers it was written from."""
    glob = [to_global(it, HOME) for it in _mission()]
    sent = _through_mavproxy(format_wpl(glob), tmp_path)
    assert [(s.frame, s.command, s.x, s.y, s.z) for s in sent] == \
        [(g.frame, g.command, g.x, g.y, g.z) for g in glob]
    assert check_mission(sent, MissionLimits(vehicle=load_vehicle(
        ROOT / "config" / "vehicles" / "hexa_tilted.toml")), HOME).result == \
        M.MAV_MISSION_ACCEPTED


# ------------------------------------------------------------------ the protocol


def _from_gcs(msg):
    msg._header.srcSystem, msg._header.srcComponent = GCS
    return msg


def test_server_keeps_the_upload_and_flies_local_items():
    """Given a server with a home, when a global mission is uploaded, then the download
    returns it as uploaded (frame and coordinates) and the flight gets the local items."""
    server = MissionServer(*VEHICLE, LIMITS, home=HOME)
    flown: list = []
    server.on_mission_changed = flown.append
    glob = [to_global(it, HOME) for it in _mission()]
    server.handle(_from_gcs(M.MAVLink_mission_count_message(*VEHICLE, len(glob), 0)), 0.0)
    for it in glob:
        out = server.handle(_from_gcs(item_message(it, *VEHICLE)), 0.0)
    assert out[-1].get_type() == "MISSION_ACK" and out[-1].type == M.MAV_MISSION_ACCEPTED
    assert server.mission == tuple(glob)
    assert flown == [server.local_mission] and all(
        it.frame == M.MAV_FRAME_LOCAL_NED for it in server.local_mission)
    back = [item_from_message(server.handle(_from_gcs(
        M.MAVLink_mission_request_int_message(*VEHICLE, i, 0)), 0.0)[0])
        for i in range(len(glob))]
    assert [b._replace(current=0) for b in back] == [g._replace(current=0) for g in glob]


def test_server_says_why_a_scaled_local_mission_is_refused(tmp_path):
    """The refusal's reason travels as STATUSTEXT chunks just before the MISSION_ACK, and
    the previous mission stays."""
    server = MissionServer(*VEHICLE, LIMITS, home=HOME)
    sent = _through_mavproxy(format_wpl(_mission()), tmp_path)
    server.handle(_from_gcs(M.MAVLink_mission_count_message(*VEHICLE, len(sent), 0)), 0.0)
    for it in sent:
        out = server.handle(_from_gcs(item_message(it, *VEHICLE)), 0.0)
    texts = [m for m in out if m.get_type() == "STATUSTEXT"]
    assert out[-1].get_type() == "MISSION_ACK" and out[-1].type == M.MAV_MISSION_DENIED
    text = "".join(m.text if isinstance(m.text, str) else m.text.decode() for m in texts)
    assert "scaled by 1e7 (MAVProxy)? use a global frame" in " ".join(text.split())
    assert server.mission == ()


any_float = st.floats(width=32) | st.sampled_from([math.nan, math.inf, -math.inf, 1e38])
any_item = st.builds(
    MissionItem, seq=st.just(0),
    frame=st.sampled_from([0, 1, 3, 5, 6, 10, 11, 12]),
    command=st.sampled_from([16, 19, 21, 22, 31000, 31001, 183]), current=st.just(0),
    autocontinue=st.just(1), param1=any_float, param2=any_float, param3=any_float,
    param4=any_float, x=st.integers(-2**31, 2**31 - 1), y=st.integers(-2**31, 2**31 - 1),
    z=any_float)


@settings(max_examples=500, deadline=None)
@given(st.lists(any_item, min_size=1, max_size=4))
def test_any_items_are_checked_without_exceptions(items):
    """Given any items in any frame (what a hostile ground station may send), then the
    vehicle's check answers a result, and what it accepts it flies in the local frame with
    x, y that fit MISSION_ITEM_INT."""
    items = [it._replace(seq=i) for i, it in enumerate(items)]
    check = check_mission(items, LIMITS, HOME)
    if check.result == M.MAV_MISSION_ACCEPTED:
        flown = localize(items, HOME)
        assert all(it.frame == M.MAV_FRAME_LOCAL_NED and it.xy_fit_int32 for it in flown)


def test_an_ordinary_geofence_breach_keeps_its_reason():
    """A local waypoint 50 m out with a 30 m fence is a geofence breach, not a scaled file;
    one 1500 m out with the 1000 m fence gets the scaling hint."""
    check = check_mission([_local(0, WP, 40.0, 30.0, -3.0)], MissionLimits(max_distance_m=30.0))
    assert check.reason == "item 0: beyond the geofence (50 m > 30 m)"
    check = check_mission([_local(0, WP, 1500.0, -750.0, -3.0)], LIMITS)
    assert check.reason.startswith("item 0: x 1500 m, y -750 m, beyond the geofence (1000 m)")
    assert check.reason.endswith("scaled by 1e7 (MAVProxy)? use a global frame")
