"""The files other ground stations read and write: QGroundControl's `.plan`, QGC WPL 110 in
global frames (what MAVProxy loads unchanged), QGC's `.params`; empty and broken files; the
CLI refusing a bad file before any network wait (gcs/mission_files/,
gcs/mission_files/param_files.py, gcs/cli/)."""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from common.links import free_port
from common.wire.mavlink import MAV, MAV_CMD_FIGURE_EIGHT, MAV_CMD_POSE_KEYFRAME
from common.wire.mission_items import GLOBAL_SCALE, HomePosition, MissionItem, local_xy, to_local
from gcs import cli
from gcs.mission_files import (
    file_format,
    format_mission,
    parse_mission,
    read_mission,
    write_mission,
)
from gcs.mission_files.frames import to_frame
from gcs.mission_files.items import MissionFileError
from gcs.mission_files.param_files import ParamEntry, ParamFileError, format_params, parse_params
from gcs.mission_files.plan import format_plan, parse_plan
from gcs.mission_files.toml import format_toml, parse_toml
from gcs.mission_files.wpl import format_wpl, parse_wpl

M = MAV
DATA = Path(__file__).resolve().parents[1] / "data"
HOME = HomePosition(47.397742, 8.545594, 488.0)


def _key(item: MissionItem):
    return tuple("nan" if isinstance(v, float) and math.isnan(v) else v for v in item)


def _same(a, b) -> bool:
    return [_key(i) for i in a] == [_key(i) for i in b]


f32 = st.floats(-1e4, 1e4, allow_nan=False, width=32)
item = st.builds(
    MissionItem, seq=st.just(0),
    frame=st.sampled_from([M.MAV_FRAME_LOCAL_NED, 0, 3, 5, 6, 10]),
    command=st.sampled_from([16, 19, 21, 22, MAV_CMD_POSE_KEYFRAME, MAV_CMD_FIGURE_EIGHT,
                             183]),
    current=st.just(0), autocontinue=st.sampled_from([0, 1]), param1=f32, param2=f32,
    param3=f32, param4=st.one_of(f32, st.just(math.nan)),
    x=st.integers(-2**31, 2**31 - 1), y=st.integers(-2**31, 2**31 - 1),
    z=st.one_of(f32, st.just(math.nan)), mission_type=st.just(0))


# ------------------------------------------------------------------ QGroundControl .plan


def test_example_plan_as_qgc_writes_it():
    """Given a plan as QGroundControl saves it (tests/data/qgc_mission.plan: takeoff,
    waypoints, a loiter and a landing in GLOBAL_RELATIVE_ALT, null yaw), then it reads as
    those items, lat/lon in 1e-7 deg rounded, null as NaN, the first item current."""
    items = read_mission(DATA / "qgc_mission.plan")
    assert [(it.command, it.frame) for it in items] == [
        (22, 3), (16, 3), (16, 3), (19, 3), (21, 3)]
    assert [it.current for it in items] == [1, 0, 0, 0, 0]
    assert all(it.autocontinue == 1 and math.isnan(it.param4) for it in items)
    assert (items[1].param1, items[1].x, items[1].y, items[1].z) == (
        2.0, 473977619, 85456174, 3.0)
    assert items[3].param1 == 3.0 and items[4].z == 0.0


def test_plan_round_trip_and_shape():
    """Given the example, when written as a plan and read again, then the items are the same,
    and the file has QGC's keys: fileType Plan, version 1, mission version 2, firmwareType 12
    (PX4), vehicleType, speeds, the home as plannedHomePosition, 7 params, doJumpId, an empty
    geofence and rally points; keys sorted, 4-space indents, NaN as null."""
    items = read_mission(DATA / "qgc_mission.plan")
    text = format_plan(items, HOME)
    assert _same(parse_plan(text), items)
    doc = json.loads(text)
    assert (doc["fileType"], doc["version"], doc["mission"]["version"]) == ("Plan", 1, 2)
    mission = doc["mission"]
    assert mission["firmwareType"] == 12 and mission["vehicleType"] == M.MAV_TYPE_HEXAROTOR
    assert mission["plannedHomePosition"] == [47.397742, 8.545594, 488.0]
    assert {"cruiseSpeed", "hoverSpeed", "globalPlanAltitudeMode"} <= set(mission)
    assert doc["geoFence"] == {"circles": [], "polygons": [], "version": 2}
    assert doc["rallyPoints"] == {"points": [], "version": 2}
    first = mission["items"][0]
    assert first["type"] == "SimpleItem" and first["doJumpId"] == 1
    assert first["autoContinue"] is True and len(first["params"]) == 7
    assert first["params"][3] is None and first["AltitudeMode"] == 1
    assert text == json.dumps(doc, indent=4, sort_keys=True) + "\n"


@settings(max_examples=200, deadline=None)
@given(st.lists(item, max_size=6))
def test_any_items_round_trip_through_plan_and_wpl(items):
    """Any items (any frame, float32 parameters, int32 x/y, NaN) survive .plan and WPL."""
    items = [it._replace(seq=i, current=int(i == 0)) for i, it in enumerate(items)]
    assert _same(parse_plan(format_plan(items)), items)
    assert _same(parse_wpl(format_wpl(items)), items)


def test_do_jump_targets_travel_as_do_jump_ids():
    """QGC's DO_JUMP p1 is the target's doJumpId (seq + 1 when written here)."""
    jump = MissionItem(1, 2, 177, 0, 1, 0.0, 3.0, 0.0, 0.0, 0, 0, 0.0)
    items = [read_mission(DATA / "qgc_mission.plan")[0], jump]
    doc = json.loads(format_plan(items, HOME))
    assert doc["mission"]["items"][1]["params"][0] == 1.0
    assert parse_plan(json.dumps(doc))[1].param1 == 0.0
    doc["mission"]["items"][1]["params"][0] = 9
    with pytest.raises(MissionFileError, match="doJumpId 9"):
        parse_plan(json.dumps(doc))


# ------------------------------------------------------------------ WPL in global frames


@settings(max_examples=500, deadline=None)
@given(st.integers(-1_800_000_000, 1_800_000_000))
def test_written_degrees_survive_truncation_and_rounding(n):
    """Given MISSION_ITEM_INT's 1e-7 deg integer, when written to WPL (and .plan), then a
    reader that truncates x * 1e7 (MAVProxy's wp load, QGC's upload) and one that rounds
    (ours) both get the integer back: written a quarter step away from zero."""
    it = MissionItem(0, M.MAV_FRAME_GLOBAL_RELATIVE_ALT, 16, 1, 1, 0.0, 0.0, 0.0, 0.0, n, -n,
                     5.0)
    fields = format_wpl([it]).splitlines()[1].split("\t")
    for text, want in ((fields[8], n), (fields[9], -n)):
        assert int(float(text) * GLOBAL_SCALE) == want == round(float(text) * GLOBAL_SCALE)
        assert abs(float(text) - want / GLOBAL_SCALE) == pytest.approx(
            0.25e-7 if want else 0.0, rel=1e-5, abs=1e-15)
    lat = json.loads(format_plan([it]))["mission"]["items"][0]["params"][4]
    assert int(lat * GLOBAL_SCALE) == n


def test_download_in_the_global_frame():
    """A local mission written with --frame global is in MAV_FRAME_GLOBAL_RELATIVE_ALT, lat
    and lon in degrees with 9 decimals or more (0.1 mm), altitude above home; converted back
    it lies within half a 1e-7 deg step (6.7 mm) of the original."""
    local = [MissionItem(0, 1, 22, 1, 1, 0.0, 0.0, 0.0, math.nan, 0, 0, -3.0),
             MissionItem(1, 1, 16, 0, 1, 2.0, 0.0, 0.0, math.nan, local_xy(2.345),
                         local_xy(-1.234), -3.0)]
    glob = to_frame(local, "global", HOME)
    lines = format_wpl(glob).splitlines()
    fields = lines[2].split("\t")
    assert fields[2] == "3" and fields[10] == "3.0"
    assert len(fields[8].split(".")[1]) >= 9 and len(fields[9].split(".")[1]) >= 9
    back = to_frame(parse_wpl("\n".join(lines)), "local", HOME)
    assert math.hypot(back[1].x_m - 2.345, back[1].y_m + 1.234) < 0.0067
    assert back[1].z == -3.0 and back[0].z == -3.0
    assert _same([to_local(glob[1], HOME)], [back[1]])
    with pytest.raises(MissionFileError, match="home position"):
        to_frame(local, "global", None)


# ------------------------------------------------------------------ empty and broken files


@pytest.mark.parametrize("fmt", ["plan", "wpl", "toml"])
def test_empty_mission_is_a_valid_file_of_its_format(tmp_path, fmt):
    """An empty mission downloads as a valid file (WPL: the header; plan: no items; TOML:
    the format line), which reads back as no items; uploading it is refused with a hint."""
    text = format_mission([], fmt, HOME)
    assert parse_mission(text, fmt) == []
    if fmt == "wpl":
        assert text == "QGC WPL 110\n"
    if fmt == "plan":
        assert json.loads(text)["mission"]["items"] == []
    path = tmp_path / f"empty.{ {'plan': 'plan', 'wpl': 'waypoints', 'toml': 'toml'}[fmt] }"
    path.write_text(text)
    with pytest.raises(MissionFileError, match="no mission items"):
        read_mission(path)


PLAN = (DATA / "qgc_mission.plan").read_text()


def _plan_with(change) -> str:
    """The example plan with `change(doc)` applied, as QGC would write it."""
    doc = json.loads(PLAN)
    change(doc)
    return json.dumps(doc, indent=4, sort_keys=True)


def _item2(doc) -> dict:
    return doc["mission"]["items"][1]


@pytest.mark.parametrize(("name", "text", "message"), [
    ("m.plan", '{"fileType": "Plan", ', "not valid JSON"),
    ("m.plan", PLAN.replace('"Plan"', '"GeoFence"'), "key 'fileType'"),
    ("m.plan", PLAN.replace('"version": 1\n}', '"version": 2\n}'), "plan version 1"),
    ("m.plan", PLAN.replace("47.39776193527411", "NaN"), "NaN is not JSON"),
    ("m.plan", PLAN.replace("47.39776193527411", "null"), "not finite"),
    ("m.plan", _plan_with(lambda d: _item2(d).update(frame=77)), "item 2: unknown frame 77"),
    ("m.plan", _plan_with(lambda d: _item2(d).update(type="ComplexItem",
                                                     complexItemType="survey")),
     r"item 2: .*only SimpleItem.*survey"),
    ("m.plan", _plan_with(lambda d: _item2(d)["params"].pop()), "item 2: .*7 values"),
    ("m.plan", _plan_with(lambda d: _item2(d).update(Altitude=5)),
     r"item 2: 'Altitude' 5 differs from params\[6\]"),
    ("m.plan", _plan_with(lambda d: _item2(d).update(autoContinue=1)), "true or false"),
    ("m.plan", _plan_with(lambda d: d.pop("mission")), "key 'mission'"),
    ("m.plan", "[1, 2]", "expected a JSON object"),
    ("m.plan", "QGC WPL 110\n", "not valid JSON"),
    ("m.waypoints", "QGC WPL 110\n0\t1\t77\t16\t0\t0\t0\t0\t0\t0\t0\t1\n", "unknown frame 77"),
    ("m.waypoints", "QGC WPL 110\n0\t1\t3\t16\t0\t0\t0\t0\tnan\t8.5\t5\t1\n", "not finite"),
    ("m.waypoints", '{"fileType": "Plan"}', "expected the header"),
    ("m.toml", '[[item]]\ntype = "raw"\ncommand = 16\nframe = 99\nparams = [0, 0, 0, 0]\n'
               "x = 0\ny = 0\nz = 0\n", "unknown frame 99"),
])
def test_broken_files_are_refused_in_one_line(tmp_path, name, text, message):
    """Syntax, a wrong fileType or version, NaN in JSON, a null or NaN coordinate, an unknown
    frame, a complex item: one line naming the file and the place."""
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(MissionFileError, match=message) as err:
        read_mission(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)


def test_formats_follow_the_extension_or_the_option(tmp_path):
    """.plan, .waypoints and .toml by extension; --format overrides; .txt and others are
    read by content and written as WPL."""
    assert [file_format(Path(n)) for n in ("a.plan", "a.waypoints", "a.toml", "a.txt")] == [
        "plan", "wpl", "toml", "wpl"]
    assert file_format(Path("a.txt"), text=PLAN) == "plan"
    assert file_format(Path("a.txt"), text="[[item]]") == "toml"
    assert file_format(Path("a.plan"), "wpl") == "wpl"
    items = read_mission(DATA / "qgc_mission.plan")
    for name, fmt, head in (("x.plan", None, "{"), ("x.waypoints", None, "QGC WPL 110"),
                            ("x.toml", None, "# Mission"), ("x.mission", None, "QGC WPL 110"),
                            ("y.txt", "plan", "{")):
        write_mission(tmp_path / name, items, fmt, HOME)
        assert (tmp_path / name).read_text().startswith(head)
        assert _same(read_mission(tmp_path / name, fmt), items)
    assert _same(parse_toml(format_toml(items)), items)  # global items as raw TOML


# ------------------------------------------------------------------ QGC .params


def test_params_file_as_qgc_writes_it():
    """Header comment as QGC writes it, tab-separated sysid compid name value type, floats
    with 18 decimals (a float32 reads back exactly)."""
    entries = [ParamEntry(1, 1, "DQ_KPR_X", 0.15000000596046448),
               ParamEntry(1, 1, "MIS_ENV_CHK", 1.0)]
    text = format_params(entries, system_id=1, stack="MAVLink Generic", vehicle="Multi-Rotor",
                         version="0.1.0", git_revision="00")
    lines = text.splitlines()
    assert lines[:8] == ["# Onboard parameters for Vehicle 1", "#", "# Stack: MAVLink Generic",
                         "# Vehicle: Multi-Rotor", "# Version: 0.1.0", "# Git Revision: 00",
                         "#", "# Vehicle-Id Component-Id Name Value Type"]
    assert lines[8] == "1\t1\tDQ_KPR_X\t0.150000005960464478\t9"
    assert parse_params(text) == entries
    # as other tools write it: spaces, integer types, blank lines
    assert parse_params("1 1 SYS_AUTOSTART 4001 6\n\n") == [
        ParamEntry(1, 1, "SYS_AUTOSTART", 4001.0, 6)]


@pytest.mark.parametrize(("text", "message"), [
    ("1\t1\tDQ_KPR_X\t1.0\n", "expected 5"),
    ("1\t1\tDQ_KPR_X\tabc\t9\n", "not a number"),
    ("1\t1\tDQ_KPR_X\tnan\t9\n", "not finite"),
    ("1\t1\tDQ_KPR_X\t1e39\t9\n", "float32"),
    ("1\t1\tDQ_KPR_X\t1.5\t6\n", "does not fit type 6"),
    ("1\t1\tDQ_KPR_X\t1\t42\n", "not a MAV_PARAM_TYPE"),
    ("1\t1\tA_NAME_LONGER_THAN_16\t1\t9\n", "not a parameter name"),
    ("x\t1\tDQ_KPR_X\t1\t9\n", "integers"),
    ("1\t1\tDQ_KPR_X\t1\t9\n1\t1\tDQ_KPR_X\t2\t9\n", "again"),
])
def test_broken_params_files(text, message):
    with pytest.raises(ParamFileError, match=message):
        parse_params(text, "p.params")


# ------------------------------------------------------------------ the CLI


@pytest.mark.parametrize("argv", [
    ["mission", "upload", "{bad}"],
    ["mission", "upload", "{bad}", "--format", "plan"],
    ["param", "load", "{badparams}"],
    ["mission", "download", "{nofolder}"],
])
def test_cli_refuses_bad_files_before_any_network_wait(tmp_path, capsys, argv):
    """A bad file ends the command with one line on stderr and exit status 2 at once, not
    after waiting --wait seconds for a vehicle that is not there."""
    bad = tmp_path / "bad.plan"
    bad.write_text('{"fileType": "Plan", "version": 1, "mission": {"version": 2, '
                   '"items": [{"type": "SimpleItem", "command": 16, "frame": 3, '
                   '"autoContinue": true, "params": [0, 0, 0, 0, NaN, 8.5, 5]}]}}')
    badparams = tmp_path / "bad.params"
    badparams.write_text("1\t1\tDQ_KPR_X\tfast\t9\n")
    paths = {"{bad}": str(bad), "{badparams}": str(badparams),
             "{nofolder}": str(tmp_path / "missing" / "m.plan")}
    t0 = time.monotonic()
    code = cli.main([paths.get(a, a) for a in argv] + [
        "--connect", f"udpin:127.0.0.1:{free_port()}", "--wait", "30"])
    err = capsys.readouterr().err
    assert code == 2 and time.monotonic() - t0 < 5.0
    assert err.startswith("gcs ") and err.count("\n") == 1


json_value = st.recursive(
    st.none() | st.booleans() | st.integers(-2**40, 2**40) | st.floats(allow_nan=False,
                                                                       allow_infinity=False)
    | st.text(max_size=5),
    lambda inner: st.lists(inner, max_size=8) | st.dictionaries(st.text(max_size=8), inner,
                                                                max_size=4),
    max_leaves=20)
item_key = st.sampled_from(["type", "command", "frame", "autoContinue", "params", "doJumpId",
                            "Altitude", "AltitudeMode"])


VALID_ITEM = json.loads(PLAN)["mission"]["items"][1]
param = st.none() | st.floats(width=64) | st.integers(-2**70, 2**70) | st.text(max_size=2)
entry = st.one_of(
    st.dictionaries(item_key, json_value | st.sampled_from(
        ["SimpleItem", 16, 3, True, [0, 0, 0, None, 47.4, 8.5, 5], 1e308]), max_size=8),
    st.builds(lambda k, v: {**VALID_ITEM, k: v}, item_key, json_value),
    st.builds(lambda ps: {**VALID_ITEM, "params": ps}, st.lists(param, min_size=7,
                                                                max_size=7)))


@settings(max_examples=300, deadline=None)
@given(st.lists(entry, max_size=4), json_value)
def test_plans_of_any_content_raise_only_mission_file_error(entries, home):
    """Any JSON in a plan's place: items, or a MissionFileError."""
    doc = json.loads(PLAN)
    doc["mission"]["items"] = entries
    doc["mission"]["plannedHomePosition"] = home
    try:
        items = parse_plan(json.dumps(doc))
    except MissionFileError:
        return
    assert all(it.xy_fit_int32 for it in items)
