"""The grammar mission generator of benchmarks/grammar_missions.py: over a few hundred
missions it draws every block, ending, file format and both kinds of start within its
stated ranges, repeatably, and each mission's file reads back as its items; the campaign's
refusal check tells a reasoned refusal from a bare one."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np

from benchmarks.grammar_mission_gen import (
    BLOCKS,
    DEFAULT,
    DO_CHANGE_SPEED,
    EXTENSION,
    FORMATS,
    NAV_TAKEOFF,
    draw_mission,
    file_items,
    item_phase,
)
from benchmarks.grammar_missions import refusal_ok
from common.wire.mission_items import PX4_SITL_HOME, to_local
from fcu.compose import published_home
from gcs.mission_files import read_mission, write_mission

HOME = published_home(PX4_SITL_HOME)


def _missions(n: int = 300) -> list:
    return [draw_mission(np.random.default_rng((0, k))) for k in range(n)]


def test_every_phase_format_and_start_within_ranges():
    missions = _missions()
    phases = Counter(p for m in missions for p in set(m.phases))
    assert set(BLOCKS) | {"takeoff", "land", "end_in_air"} == set(phases)
    assert set(m.fmt for m in missions) == set(FORMATS)
    starts = [math.hypot(*m.start_enu_m[:2]) for m in missions]
    assert min(starts) == 0.0 and 0.0 < max(starts) <= DEFAULT.start_radius_m
    assert all(m.start_enu_m[2] == 0.0 for m in missions)
    for m in missions:
        assert 0.05 <= m.params["MIS_LAND_SPD"] <= 5.0
        for it in m.items:
            if it.command == NAV_TAKEOFF:
                assert 0.2 <= -it.z <= 3.0
            if it.command == DO_CHANGE_SPEED:
                assert it.param1 in (0.0, 1.0, 2.0, 3.0)
                assert it.param2 in (-1.0, -2.0) or it.param2 > 0.0
    kinds = Counter(item_phase(m.items, s) for m in missions for s in range(len(m.items)))
    assert {"takeoff", "cruise", "keyframe_figure", "speed", "touch_and_go", "land"} \
        <= set(kinds)


def test_repeatable_and_files_read_back(tmp_path):
    a, b = draw_mission(np.random.default_rng(7)), draw_mission(np.random.default_rng(7))
    assert repr(a) == repr(b)
    for k, m in enumerate(_missions(40)):
        path = tmp_path / f"m{k}{EXTENSION[m.fmt]}"
        write_mission(path, file_items(m, HOME), home=HOME)
        back = [to_local(it, HOME) for it in read_mission(path)]
        assert [it.command for it in back] == [it.command for it in m.items]
        for got, want in zip(back, m.items, strict=True):
            if want.command in (16, 19, 31000):  # waypoint, loiter, keyframe
                assert abs(got.x - want.x) <= 100 and abs(got.y - want.y) <= 100  # 1 cm
            assert got.z == want.z or abs(got.z - want.z) < 1e-3


def test_refusal_check():
    assert refusal_ok("mission refused: MAV_MISSION_DENIED: item 2: tilt servo 5 needs 9 "
                      "rad/s, limit 3.0")[0]
    assert not refusal_ok("mission refused: MAV_MISSION_RESULT 3:")[0]
    assert not refusal_ok("mission refused: MAV_MISSION_UNSUPPORTED")[0]
    assert not refusal_ok("mission refused: MAV_MISSION_DENIED: item 2:")[0]
