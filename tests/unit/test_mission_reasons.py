"""Every mission refusal says why: the MAV_MISSION_RESULT by name, the item and the reason,
in-process (`fcu.compose.accept_mission`, `gcs run --in-process`) as through the FCU's
ground-station link (STATUSTEXT chunks before the MISSION_ACK); hints within MIS_ITEM_MAX_S;
the geofence's comparison true as printed."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest

from common.config.scenario import load_gains, load_scenario, load_vehicle
from common.wire.mavlink import MAV, encoder, pack, parser
from common.wire.mission_items import HomePosition, MissionItem, local_xy
from fcu.compose import accept_mission, fcu_pipeline
from fcu.mission.codes import MAV_CMD_POSE_KEYFRAME, result_name
from fcu.mission.limits import MissionLimits
from fcu.mission.validation import check_mission, compared, refusal
from fcu.params import ParamError, ParamStore, mission_limits
from gcs.vehicle_link.status_texts import StatusTexts
from tests.unit.test_gcs_dispatch import make_server, parsed

M = MAV
ROOT = Path(__file__).resolve().parents[2]
NAN = math.nan
TILTED = load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml")
LOCAL = M.MAV_FRAME_LOCAL_NED


def item(seq: int, command: int, p1: float = 0.0, p2: float = 0.0, p3: float = 0.0,
         p4: float = NAN, north_m: float = 0.0, z: float = -3.0) -> MissionItem:
    return MissionItem(seq, LOCAL, command, int(seq == 0), 1, p1, p2, p3, p4,
                       local_xy(north_m), 0, z)


TAKEOFF = item(0, M.MAV_CMD_NAV_TAKEOFF)
WAYPOINT = item(1, M.MAV_CMD_NAV_WAYPOINT, north_m=2.0)


@pytest.mark.parametrize(("bad", "result"), [
    (WAYPOINT._replace(command=M.MAV_CMD_DO_SET_SERVO), M.MAV_MISSION_UNSUPPORTED),
    (WAYPOINT._replace(command=17), M.MAV_MISSION_UNSUPPORTED),
    (WAYPOINT._replace(frame=M.MAV_FRAME_BODY_FRD), M.MAV_MISSION_UNSUPPORTED_FRAME),
    (WAYPOINT._replace(frame=M.MAV_FRAME_GLOBAL_INT), M.MAV_MISSION_UNSUPPORTED_FRAME),
    (WAYPOINT._replace(x=2 ** 31), M.MAV_MISSION_INVALID_PARAM5_X),
    (WAYPOINT._replace(y=-2 ** 31 - 1), M.MAV_MISSION_INVALID_PARAM6_Y),
    (WAYPOINT._replace(param1=-1.0), M.MAV_MISSION_INVALID_PARAM1),
    (WAYPOINT._replace(param4=math.inf), M.MAV_MISSION_INVALID_PARAM4),
    (WAYPOINT._replace(z=NAN), M.MAV_MISSION_INVALID_PARAM7),
    (item(1, MAV_CMD_POSE_KEYFRAME, p1=0.0), M.MAV_MISSION_INVALID_PARAM1),
    (item(1, 31001, p1=1.0, p2=10.0, p4=0.0, z=0.0), M.MAV_MISSION_INVALID_PARAM3),
    (WAYPOINT._replace(seq=2), M.MAV_MISSION_INVALID_SEQUENCE),
    (item(1, M.MAV_CMD_NAV_WAYPOINT, north_m=2000.0), M.MAV_MISSION_DENIED),
])
def test_every_item_refusal_names_the_result_the_item_and_why(bad, result):
    """Given a mission with one bad item, then the check names the item in its reason and
    `refusal` puts the result's name first (never a bare number, never an empty reason)."""
    check = check_mission([TAKEOFF, bad], MissionLimits())
    assert check.result == result and check.seq == bad.seq
    assert check.reason.startswith(f"item {bad.seq}")
    assert len(check.reason) > len(f"item {bad.seq}: ")
    assert refusal(check) == f"{result_name(result)}: {check.reason}"
    assert refusal(check).startswith("MAV_MISSION_") and "RESULT" not in refusal(check)


def test_unsupported_command_reason_names_the_command():
    check = check_mission([TAKEOFF, WAYPOINT._replace(command=M.MAV_CMD_DO_SET_SERVO)],
                          MissionLimits())
    assert refusal(check) == ("MAV_MISSION_UNSUPPORTED: item 1: command 183 "
                              "(MAV_CMD_DO_SET_SERVO) is not supported")


def test_no_space_says_the_count_and_the_limit():
    items = [TAKEOFF, *(WAYPOINT._replace(seq=k) for k in range(1, 501))]
    check = check_mission(items, MissionLimits())
    assert (check.result, check.seq) == (M.MAV_MISSION_NO_SPACE, None)
    assert refusal(check) == "MAV_MISSION_NO_SPACE: 501 items: the vehicle holds at most 500"
    assert check_mission(items[:500], MissionLimits()).result == M.MAV_MISSION_ACCEPTED


def test_accepted_mission_has_no_refusal():
    check = check_mission([TAKEOFF, WAYPOINT], MissionLimits())
    assert check.result == M.MAV_MISSION_ACCEPTED and refusal(check) == ""


def test_result_name_of_an_unknown_number():
    assert result_name(M.MAV_MISSION_UNSUPPORTED) == "MAV_MISSION_UNSUPPORTED"
    assert result_name(250) == "MAV_MISSION_RESULT 250"


def test_accept_mission_in_process_says_the_same_as_the_protocol():
    """Given the in-process composition, then its refusal is the result by name, the item
    and the reason (it read "MAV_MISSION_RESULT 3:" before)."""
    pipeline, _ = fcu_pipeline(TILTED, load_gains(ROOT / "config/gains/pid_eq30.toml"), 500)
    home = HomePosition.published(47.0, 8.0, 400.0)
    bad = [TAKEOFF, WAYPOINT._replace(command=M.MAV_CMD_DO_SET_SERVO)]
    assert accept_mission(pipeline, bad, home) == refusal(
        check_mission(bad, pipeline.commander.limits, home))
    assert accept_mission(pipeline, bad, home).startswith("MAV_MISSION_UNSUPPORTED: item 1: ")
    assert accept_mission(pipeline, [TAKEOFF, WAYPOINT], home) == ""


# ---------------------------------------------------------------------------- geofence


@pytest.mark.parametrize(("above", "below", "texts"), [
    (50.0, 30.0, ("50", "30")),
    (1000.0004, 1000.0, ("1000.0004", "1000")),
    (1000.4, 1000.0, ("1000.4", "1000")),
    (30.6, 30.5, ("30.6", "30.5")),
    (1000.000001, 1000.0, ("1000.000001", "1000")),
    (30.04, 30.0, ("30.04", "30")),
    (0.15, 0.1, ("0.15", "0.1")),
])
def test_compared_is_true_as_printed(above, below, texts):
    assert compared(above, below) == texts
    a, b = compared(above, below)
    assert float(a) > float(b)


def test_geofence_refusal_compares_what_it_means():
    """Given a waypoint 1000 m north and 5 cm up (1000.00000125 m from the origin) and a
    1000 m fence, then the refusal reads a distance above the fence (it read "1000 m >
    1000 m")."""
    far = item(1, M.MAV_CMD_NAV_WAYPOINT, north_m=1000.0, z=-0.05)
    check = check_mission([TAKEOFF._replace(z=-0.05), far], MissionLimits())
    assert check.result == M.MAV_MISSION_DENIED
    m = re.fullmatch(r"item 1: beyond the geofence \(([0-9.]+) m > ([0-9.]+) m\)", check.reason)
    assert m is not None, check.reason
    assert float(m.group(1)) > float(m.group(2)) == 1000.0
    assert abs(float(m.group(1)) - math.hypot(1000.0, 0.05)) < 1e-6


# ---------------------------------------------------------------------------- hints


def _fast_keyframe(p1: float) -> list[MissionItem]:
    return [TAKEOFF, item(1, MAV_CMD_POSE_KEYFRAME, p1=p1, p4=0.0, north_m=2.0)]


def test_hint_within_mis_item_max_s_proposes_a_duration():
    check = check_mission(_fast_keyframe(0.5), MissionLimits(vehicle=TILTED))
    assert check.result == M.MAV_MISSION_DENIED
    proposed = float(check.reason.split("lengthen p1 to ")[1][:-2])
    assert 0.5 < proposed <= MissionLimits().item_max_s
    assert check_mission(_fast_keyframe(proposed),
                         MissionLimits(vehicle=TILTED)).result == M.MAV_MISSION_ACCEPTED


def test_hint_beyond_mis_item_max_s_is_a_refusal_saying_so():
    """Given a longest item shorter than the duration that would pass, then the refusal
    proposes none and says that none up to MIS_ITEM_MAX_S flies it."""
    check = check_mission(_fast_keyframe(0.5), MissionLimits(vehicle=TILTED))
    proposed = float(check.reason.split("lengthen p1 to ")[1][:-2])
    bounded = MissionLimits(vehicle=TILTED, item_max_s=math.floor(proposed * 10) / 10 - 0.1)
    check = check_mission(_fast_keyframe(0.5), bounded)
    assert check.result == M.MAV_MISSION_DENIED and check.seq == 1
    assert "lengthen" not in check.reason
    assert check.reason.endswith(
        f": not flyable with p1 up to MIS_ITEM_MAX_S ({bounded.item_max_s:g} s)")
    assert check.reason.startswith("item 1: ")


def test_mis_item_max_s_parameter():
    """MIS_ITEM_MAX_S: 600 s by default, 1..86400, and it sets MissionLimits.item_max_s."""
    store = ParamStore(load_gains(ROOT / "config/gains/pid_eq30.toml"))
    assert store.values["MIS_ITEM_MAX_S"] == 600.0 == MissionLimits().item_max_s
    store.set("MIS_ITEM_MAX_S", 30.0)
    assert mission_limits(store.values).item_max_s == 30.0
    for bad in (0.5, 86401.0):
        with pytest.raises(ParamError):
            store.set("MIS_ITEM_MAX_S", bad)
    with pytest.raises(ValueError):
        MissionLimits(item_max_s=0.0)


# ---------------------------------------------------------------------------- the link


def _texts(msgs) -> tuple[str, ...]:
    texts = StatusTexts()
    for m in msgs:
        if m.get_type() == "STATUSTEXT":
            texts.add(m)
    return texts.texts


def _upload(server, items, now_s: float = 1.0):
    def sent(msg):
        return parser().parse_buffer(pack(encoder(255, 190), msg))[0]
    server.handle(0, sent(M.MAVLink_mission_count_message(1, 1, len(items), 0)), now_s=now_s)
    for it in items:
        server.handle(0, sent(M.MAVLink_mission_item_int_message(
            1, 1, it.seq, it.frame, it.command, it.current, it.autocontinue, it.param1,
            it.param2, it.param3, it.param4, it.x, it.y, it.z, 0)), now_s=now_s)


def test_the_fcu_link_sends_a_long_reason_in_chunks_that_read_back_as_one():
    """Given a refusal whose reason is longer than one STATUSTEXT, then the FCU's GCS link
    sends its chunks with one id and their chunk_seq, and the ground station reads the whole
    reason back (the chunks were sent with id 0 before: read as two texts)."""
    server, links = make_server()
    items = [TAKEOFF, WAYPOINT._replace(command=M.MAV_CMD_DO_SET_SERVO)]
    _upload(server, items)
    msgs = parsed(links[0])
    chunks = [m for m in msgs if m.get_type() == "STATUSTEXT"]
    assert len(chunks) == 2 and chunks[0].id == chunks[1].id != 0
    assert [c.chunk_seq for c in chunks] == [0, 1]
    assert _texts(msgs) == (check_mission(items, MissionLimits()).reason,)
    assert [m.type for m in msgs if m.get_type() == "MISSION_ACK"] == \
        [M.MAV_MISSION_UNSUPPORTED]


def test_the_fcu_link_says_the_limit_of_no_space():
    server, links = make_server()
    server.handle(0, parser().parse_buffer(pack(encoder(255, 190), M.MAVLink_mission_count_message(
        1, 1, 501, 0)))[0], now_s=1.0)
    msgs = parsed(links[0])
    assert _texts(msgs) == ("501 items: the vehicle holds at most 500",)
    assert [m.type for m in msgs if m.get_type() == "MISSION_ACK"] == [M.MAV_MISSION_NO_SPACE]


# ---------------------------------------------------------------------------- gcs run


def _refused_scenario(tmp_path: Path) -> Path:
    mission = tmp_path / "refused.waypoints"
    mission.write_text("QGC WPL 110\n"
                       "0\t1\t1\t22\t0\t0\t0\tnan\t0\t0\t-2\t1\n"
                       "1\t0\t1\t183\t1\t1500\t0\t0\t0\t0\t0\t1\n"
                       "2\t0\t1\t21\t0\t0\t0\tnan\t0\t0\t0\t1\n")
    text = (ROOT / "config/scenarios/mission_tour.toml").read_text()
    text = text.replace('"../', f'"{ROOT}/config/').replace(
        f'"{ROOT}/config/missions/tour.toml"', f'"{mission}"')
    path = tmp_path / "refused.toml"
    path.write_text(text)
    return path


def test_refused_in_process_run_writes_aborted_metrics(tmp_path, capsys):
    """Given a scenario whose mission the vehicle refuses, then `gcs run --in-process`
    exits 1 and writes metrics.json with status aborted and the refusal as `error` (named,
    with the item), as a run through processes does; the refusal is printed."""
    from gcs.cli import main
    from gcs.run.inprocess import InProcessError, run_scenario

    scenario = _refused_scenario(tmp_path)
    with pytest.raises(InProcessError) as raised:
        run_scenario(load_scenario(scenario))
    assert raised.value.result is not None
    assert raised.value.result.metrics["status"] == "aborted"
    out = tmp_path / "run"
    assert main(["run", str(scenario), "--in-process", "--out", str(out)]) == 1
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["status"] == "aborted" and metrics["mission_completed"] is False
    assert metrics["error"] == ("mission refused: MAV_MISSION_UNSUPPORTED: item 1: command "
                                "183 (MAV_CMD_DO_SET_SERVO) is not supported")
    assert metrics["samples"] == 0 and metrics["transport"] == "in-process"
    assert set(metrics["logs"]) == {"truth.ulg", "onboard.ulg"}
    assert (out / "truth.ulg").exists() and (out / "onboard.ulg").exists()
    captured = capsys.readouterr()
    assert "mission refused: MAV_MISSION_UNSUPPORTED: item 1:" in captured.err
    assert "aborted" in captured.out and "metrics.json" in captured.out


# ----------------------------------------------------------------------------------------
# DO_CHANGE_SPEED
# ----------------------------------------------------------------------------------------


def _speed(seq: int, kind: float, speed: float, frame: int = 2) -> MissionItem:
    """DO_CHANGE_SPEED as QGC writes it (MAV_FRAME_MISSION, x = y = z = 0, throttle -1)."""
    return MissionItem(seq, frame, MAV.MAV_CMD_DO_CHANGE_SPEED, 0, 1, kind, speed, -1.0, 0.0,
                       0, 0, 0.0, MAV.MAV_MISSION_TYPE_MISSION)


@pytest.mark.parametrize(("kind", "speed", "result", "reason"), [
    (7.0, 1.0, "MAV_MISSION_INVALID_PARAM1",
     "item 1: p1 7: must be a speed type: 0 air, 1 ground, 2 climb or 3 descent speed"),
    (1.0, 0.0, "MAV_MISSION_INVALID_PARAM2",
     "item 1: p2 0: must be a speed > 0 m/s, -1 (no change) or -2 (the default)"),
    (1.0, math.nan, "MAV_MISSION_INVALID_PARAM2",
     "item 1: p2 nan: must be a speed > 0 m/s, -1 (no change) or -2 (the default)"),
])
def test_a_bad_speed_change_is_refused_naming_the_item(kind, speed, result, reason):
    """Given DO_CHANGE_SPEED with a speed type or a speed MAVLink does not define, then the
    mission is refused naming the parameter, the item and what it must be."""
    items = [TAKEOFF, _speed(1, kind, speed), item(2, M.MAV_CMD_NAV_WAYPOINT, north_m=2.0)]
    check = check_mission(items, MissionLimits())
    assert refusal(check) == f"{result}: {reason}"


def test_speed_changes_time_the_legs_after_them():
    """Given a take-off to 3 m, DO_CHANGE_SPEED ground 0.5 m/s, a 2 m leg, DO_CHANGE_SPEED -2
    (the default, MIS_CRUISE_SPD 1 m/s here), a 2 m leg back, climb speed 0.25 m/s and a
    climb of 1 m, descent speed 0.2 m/s and a landing, then without the envelope each leg
    takes 1.875 distance / the speed in force, its top speed (7.5 s, 3.75 s, 7.5 s, 37.5 s),
    and the speed items take no
    time; the same mission is accepted in any frame QGC or MAVProxy writes them in (2, 0, 3)."""
    from fcu.mission.executor import MissionExecutor
    for frame in (2, 0, 3):
        items = [TAKEOFF, _speed(1, 1.0, 0.5, frame),
                 item(2, M.MAV_CMD_NAV_WAYPOINT, p1=0.0, north_m=2.0),
                 _speed(3, 0.0, -2.0, frame), item(4, M.MAV_CMD_NAV_WAYPOINT, p1=0.0),
                 _speed(5, 2.0, 0.25, frame),
                 item(6, M.MAV_CMD_NAV_TAKEOFF, z=-4.0), _speed(7, 3.0, 0.2, frame),
                 item(8, M.MAV_CMD_NAV_LAND)]
        limits = MissionLimits(cruise_speed_m_s=1.0)
        assert refusal(check_mission(items, limits)) == ""
        ex = MissionExecutor(items, limits)
        ex.start(0.0, (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))
        spans = {seq: t1 - t0 for seq, t0, t1 in ex.schedule}
        assert [spans[k] for k in (1, 3, 5, 7)] == [0.0] * 4
        assert [spans[k] for k in (2, 4, 6, 8)] == pytest.approx([7.5, 3.75, 7.5, 37.5])
    ex.set_current(4, 0.0, (0.0, 2.0, 3.0), (1.0, 0.0, 0.0, 0.0))  # resumed after item 3
    assert {seq: t1 - t0 for seq, t0, t1 in ex.schedule}[4] == pytest.approx(3.75)
