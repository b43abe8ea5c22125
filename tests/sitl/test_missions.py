"""The mission protocol against the real FCU process: round trip and atomicity."""

from __future__ import annotations

import math

import pytest

from common.config.scenario import load_scenario
from common.wire.mavlink import MAV, MAV_CMD_POSE_KEYFRAME
from common.wire.mission_items import MissionItem, local_xy
from gcs.run.scenario_mission import scenario_mission
from gcs.vehicle_link.mission_client import clear, download, upload

from .conftest import SCENARIOS

M = MAV
pytestmark = pytest.mark.timeout(120)


def _same(a: list[MissionItem], b: list[MissionItem]) -> bool:
    def key(i: MissionItem):
        return (i.seq, i.frame, i.command, i.autocontinue, i.x, i.y,
                *(None if math.isnan(v) else v for v in (i.param1, i.param2, i.param3,
                                                          i.param4, i.z)))
    return [key(i) for i in a] == [key(i) for i in b]


def test_upload_download_round_trip_and_atomic_refusal(stack):
    """Case I's mission goes up and comes back unchanged; a mission with an unsupported
    command, a bad frame or a NaN parameter is refused with its specific result and the
    previous mission stays; clear empties it."""
    s = stack.session
    t, c = s.target_system, s.target_component
    case1 = scenario_mission(load_scenario(SCENARIOS / "case1_figure8.toml"))
    assert upload(s.conn, t, c, case1, send=s.send) == M.MAV_MISSION_ACCEPTED
    back = download(s.conn, t, c, send=s.send)
    assert _same(back, case1)

    # parameters travel as float32: pick values that survive exactly
    keyframe = MissionItem(0, M.MAV_FRAME_LOCAL_NED, MAV_CMD_POSE_KEYFRAME, 1, 1, 4.0, 0.125,
                           0.25, -0.375, local_xy(1.5), local_xy(-2.25), -3.0)
    unsupported = keyframe._replace(command=M.MAV_CMD_DO_SET_SERVO)
    # global frames with an altitude are converted through the home; terrain ones are not
    bad_frame = keyframe._replace(frame=M.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT)
    bad_param = keyframe._replace(param1=math.nan)
    for items, expected in (([keyframe, unsupported.with_seq(1)], M.MAV_MISSION_UNSUPPORTED),
                            ([bad_frame], M.MAV_MISSION_UNSUPPORTED_FRAME),
                            ([bad_param], M.MAV_MISSION_INVALID_PARAM1)):
        assert upload(s.conn, t, c, items, send=s.send) == expected
        assert _same(download(s.conn, t, c, send=s.send), case1)

    assert upload(s.conn, t, c, [keyframe], send=s.send) == M.MAV_MISSION_ACCEPTED
    assert _same(download(s.conn, t, c, send=s.send), [keyframe])
    assert clear(s.conn, t, c, send=s.send) == M.MAV_MISSION_ACCEPTED
    assert download(s.conn, t, c, send=s.send) == []
