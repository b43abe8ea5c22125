"""The phase-by-phase mission generator of benchmarks/phase_missions.py: over a few dozen
missions it draws every phase, every file format and both kinds of start, within the
stated ranges, and each mission reads back from its file as the same flight."""

from __future__ import annotations

import math
from collections import Counter

import pytest

from benchmarks.phase_missions import FORMATS, VEHICLES, draw_mission, written
from common.wire.mav_enums import MAV_CMD
from common.wire.mission_items import PX4_SITL_HOME, to_local
from fcu.compose import published_home
from gcs.mission_files import read_mission


def test_the_generator_draws_every_phase_format_and_start():
    missions = [draw_mission(0, k, v) for v in VEHICLES for k in range(60)]
    phases = Counter(p for m in missions for p in set(m["phases"]))
    assert set(phases) == {"take-off", "cruise", "speed", "cruise after a speed change",
                           "loiter", "keyframe", "touch-and-go", "landing"}
    assert set(Counter(m["format"] for m in missions)) == set(FORMATS)
    starts = [math.hypot(*m["start_enu_m"][:2]) for m in missions]
    assert min(starts) == 0.0 and 0.0 < max(starts) <= 5.0
    assert all(0.05 <= m["land_m_s"] <= 5.0 for m in missions)
    climbs = [-it.z for m in missions for it in m["items"]
              if it.command == MAV_CMD.MAV_CMD_NAV_TAKEOFF]
    assert 0.2 <= min(climbs) < 0.5 and 2.5 < max(climbs) <= 3.0
    assert all(m["items"][-1].command == MAV_CMD.MAV_CMD_NAV_LAND for m in missions)
    assert draw_mission(0, 7, VEHICLES[0]) == draw_mission(0, 7, VEHICLES[0])  # repeatable


@pytest.mark.parametrize("fmt", FORMATS)
def test_a_written_mission_reads_back_as_the_same_flight(tmp_path, fmt):
    """Given a drawn mission written in each format, then reading it back and converting
    global positions through the same home gives the same commands and positions (to the
    resolution of the file: 1e-7 deg for global positions)."""
    m = next(m for k in range(60) for m in [draw_mission(1, k, VEHICLES[1])]
             if "speed" in m["phases"] and "keyframe" in m["phases"])
    back = read_mission(written(m["items"], fmt, tmp_path))
    home = published_home(PX4_SITL_HOME)
    assert [it.command for it in back] == [it.command for it in m["items"]]
    for a, b in zip((to_local(it, home) for it in back), m["items"], strict=True):
        if b.command in (MAV_CMD.MAV_CMD_NAV_WAYPOINT, 31000):
            # 1e-7 deg of latitude is 1.1 cm: x, y in 1e-4 m within 120
            assert abs(a.x - b.x) <= 120 and abs(a.y - b.y) <= 120 and a.z == pytest.approx(b.z,
                                                                                        abs=1e-3)
        assert a.param2 == pytest.approx(b.param2, rel=1e-6, abs=1e-6)
