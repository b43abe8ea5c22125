"""Mission files: QGC WPL 110 and the TOML form, both ways, and their errors."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from common.config.scenario import load_scenario
from common.wire.mavlink import MAV, MAV_CMD_FIGURE_EIGHT, MAV_CMD_POSE_KEYFRAME
from common.wire.mission_items import MissionItem
from gcs.mission_files import read_mission, write_mission
from gcs.mission_files.items import MissionFileError
from gcs.mission_files.toml import format_toml, parse_toml
from gcs.mission_files.wpl import format_wpl, parse_wpl
from gcs.run.scenario_mission import scenario_mission

from ..closed_loop.conftest import SCENARIOS

M = MAV


def _key(item: MissionItem):
    return tuple("nan" if isinstance(v, float) and math.isnan(v) else v for v in item)


def _same(a, b) -> bool:
    return [_key(i) for i in a] == [_key(i) for i in b]


CASE1 = scenario_mission(load_scenario(SCENARIOS / "case1_figure8.toml"))

f32 = st.floats(-1e4, 1e4, allow_nan=False, width=32)
item = st.builds(
    MissionItem, seq=st.just(0), frame=st.sampled_from([M.MAV_FRAME_LOCAL_NED, 0, 6]),
    command=st.sampled_from([16, 19, 21, 22, MAV_CMD_POSE_KEYFRAME, MAV_CMD_FIGURE_EIGHT,
                             183]),
    current=st.just(0), autocontinue=st.sampled_from([0, 1]), param1=f32, param2=f32,
    param3=f32, param4=st.one_of(f32, st.just(math.nan)),
    x=st.integers(-2**31, 2**31 - 1), y=st.integers(-2**31, 2**31 - 1), z=f32,
    mission_type=st.just(0))


@settings(max_examples=200, deadline=None)
@given(st.lists(item, min_size=1, max_size=6))
def test_any_items_round_trip_through_both_formats(items):
    """Any items (float32 parameters, int32 x/y, any frame and command) survive both files."""
    items = [it._replace(seq=i, current=int(i == 0)) for i, it in enumerate(items)]
    assert _same(parse_wpl(format_wpl(items)), items)
    assert _same(parse_toml(format_toml(items)), items)


def test_case1_reads_as_named_items_in_toml():
    """The Case I mission in TOML is readable: takeoff, loiter, figure_eight, loiter."""
    text = format_toml(CASE1)
    assert [line for line in text.splitlines() if line.startswith("type")] == [
        'type = "takeoff"', 'type = "loiter"', 'type = "figure_eight"', 'type = "loiter"']
    assert "axis_ned = [2.0, 1.0, -3.0]" in text and "yaw_deg = nan" in text
    assert _same(parse_toml(text), CASE1)


def test_wpl_is_the_format_qgc_and_mavproxy_share():
    """Header, tab-separated 12 fields, local x/y in metres, index/current/frame/command."""
    lines = format_wpl(CASE1).splitlines()
    assert lines[0] == "QGC WPL 110"
    fields = lines[3].split("\t")
    assert len(fields) == 12 and fields[:4] == ["2", "0", "1", str(MAV_CMD_FIGURE_EIGHT)]
    assert fields[4:7] == ["5.0", "120.0", "2.0"] and fields[-1] == "1"
    # a MAVProxy-style file with spaces and a global item
    text = "QGC WPL 110\n0 1 3 16 0 0 0 0 47.3977419 8.5455938 10.0 1\n"
    (it,) = parse_wpl(text)
    assert it.frame == 3 and it.x == 473977419 and it.y == 85455938 and it.z == 10.0


def test_keyframe_in_toml():
    """A 6-DoF keyframe in TOML maps onto the slots of command 31000."""
    text = ('[[item]]\ntype = "keyframe"\nposition_ned_m = [1.5, -2.25, -3.0]\n'
            "time_s = 4.0\nrotvec_ned_frd_rad = [0.125, -0.25, 0.5]\n")
    (it,) = parse_toml(text)
    assert (it.command, it.frame, it.param1, it.param2, it.param3, it.param4) == (
        MAV_CMD_POSE_KEYFRAME, M.MAV_FRAME_LOCAL_NED, 4.0, 0.125, -0.25, 0.5)
    assert (it.x, it.y, it.z) == (15000, -22500, -3.0)


@pytest.mark.parametrize(("text", "message"), [
    ("QGC WPL 120\n", "version 110"),
    ("QGC WPL 110\n0\t1\t1\t16\t0\n", "line 2: expected 12 fields"),
    ("QGC WPL 110\n0\t1\t1\tsixteen\t0\t0\t0\t0\t0\t0\t0\t1\n", "line 2"),
    ("QGC WPL 110\n0\t1\t1\t16\t0\t0\t0\t0\t1e9\t0\t0\t1\n", "int32"),
    ('[[item]]\ntype = "jump"\n', "key 'type'"),
    ('[[item]]\ntype = "loiter"\ntime_s = 3\n', "position_ned_m"),
    ('[[item]]\ntype = "loiter"\ntime_s = 3\nposition_ned_m = [0, 0, 0]\nspeed = 2\n',
     "unknown key 'speed'"),
    ('[[item]]\ntype = "waypoint"\nposition_ned_m = [0, "a", 0]\n', "3 numbers"),
    ("mission = [", "not valid TOML"),
])
def test_broken_files_are_refused_with_the_place_and_reason(tmp_path, text, message):
    path = tmp_path / "m.txt"
    path.write_text(text)
    with pytest.raises(MissionFileError, match=message) as err:
        read_mission(path)
    assert str(path) in str(err.value)


def test_empty_and_missing_files(tmp_path):
    empty = tmp_path / "empty.toml"
    empty.write_text('format = "dqflight-mission-1"\n')
    with pytest.raises(MissionFileError, match="no mission items"):
        read_mission(empty)
    with pytest.raises(MissionFileError, match="No such file"):
        read_mission(tmp_path / "nope.toml")


def test_write_by_extension_or_format(tmp_path):
    write_mission(tmp_path / "a.toml", CASE1)
    write_mission(tmp_path / "a.waypoints", CASE1)
    write_mission(tmp_path / "b.txt", CASE1, "toml")
    assert (tmp_path / "a.toml").read_text().startswith("# Mission")
    assert (tmp_path / "a.waypoints").read_text().startswith("QGC WPL 110")
    assert (tmp_path / "b.txt").read_text() == (tmp_path / "a.toml").read_text()
    for name in ("a.toml", "a.waypoints", "b.txt"):
        assert _same(read_mission(tmp_path / name), CASE1)
