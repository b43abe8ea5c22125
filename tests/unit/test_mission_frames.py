"""Mission items keep the frame their file gives, both ways, on every autopilot: a .plan,
WPL or TOML file with items in MAV_FRAME_GLOBAL (0), GLOBAL_RELATIVE_ALT (3),
GLOBAL_TERRAIN_ALT (10), their _INT forms (5, 6, 11), MAV_FRAME_MISSION (2) and (WPL and
TOML to PX4) LOCAL_NED (1) goes to a scripted vehicle over loopback UDP in MISSION_ITEM_INT
with those frame numbers and degE7 integers, and downloads back to the same items, the
_INT frames as their plain ones (neither firmware keeps the difference: PX4 answers in
the _INT frames whatever was uploaded, ArduPilot in the plain ones)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from common.wire.mavlink import MAV
from common.wire.mission_items import HomePosition, MissionItem
from gcs.mission_files import format_mission, parse_mission
from tests.unit.scripted_autopilot import HOME, ScriptedAutopilot, gcs

M = MAV
pytestmark = pytest.mark.timeout(60)
NAN = math.nan
LAT, LON = -353632621, 1491652374


def item(seq: int, frame: int, command: int = 16, dx: int = 0, z: float = 10.0,
         p1: float = 0.0) -> MissionItem:
    x, y = (LAT + dx, LON - dx) if frame != 1 and frame != 2 else (dx, -dx)
    return MissionItem(seq, frame, command, int(seq == 0), 1, p1, 0.0, 0.0, NAN, x, y, z)


GLOBAL = [item(0, 3, 22, z=5.0), item(1, 3, dx=1234), item(2, 0, dx=2345, z=600.0),
          item(3, 10, dx=3456, z=7.5), item(4, 6, dx=4567), item(5, 5, dx=5678, z=601.25),
          item(6, 11, dx=6789), item(7, 2, 178, z=0.0, p1=1.0), item(8, 3, 21, z=0.0)]
PX4_ONLY = [*GLOBAL[:8], item(8, 1, dx=25000, z=-4.0), item(9, 3, 21, z=0.0)]


class Recorder(ScriptedAutopilot):
    """A scripted vehicle that keeps each mission item message as it came."""

    def __init__(self, kind: str) -> None:
        self.wire: list[tuple[str, int, int, int]] = []  # (type, frame, x, y)
        super().__init__(kind)

    def _handle(self, msg) -> None:
        if msg.get_type() in ("MISSION_ITEM_INT", "MISSION_ITEM"):
            self.wire.append((msg.get_type(), msg.frame, msg.x, msg.y))
        super()._handle(msg)


@pytest.fixture
def vehicles():
    made: list[ScriptedAutopilot] = []

    def make(kind: str) -> Recorder:
        v = Recorder(kind)
        made.append(v)
        return v

    yield make
    for v in made:
        v.close()




def plan_items(path: Path) -> list[dict]:
    return json.loads(path.read_text())["mission"]["items"]


# A plan downloads its local items in GLOBAL_RELATIVE_ALT unless --frame local (QGC shows no
# local frame: docs/ground-station.md), so the plans here are global.
CASES = [("px4", GLOBAL, 12), ("ardupilot", GLOBAL, 3)]


@pytest.mark.parametrize("kind,items,firmware", CASES)
def test_plan_round_trip_keeps_every_frame(vehicles, capsys, tmp_path, kind, items, firmware):
    """Given a plan of items in frames 0, 3, 10, 5, 6, 11, 2, when it is
    uploaded and downloaded again, then each went in MISSION_ITEM_INT with its own frame
    number and degE7 x, y, and the plan's items are identical (frames, commands, params,
    coordinates)."""
    v = vehicles(kind)
    src = tmp_path / "src.plan"
    src.write_text(format_mission(items, "plan", HomePosition(*HOME),
                                  firmware_type=firmware))
    code, out, err = gcs(capsys, v, "mission", "upload", str(src))
    assert code == 0, out + err
    sent = v.wire[1:] if kind == "ardupilot" else v.wire  # ArduPilot: home at seq 0 first
    assert sent == [("MISSION_ITEM_INT", it.frame, it.x, it.y) for it in items]
    back = tmp_path / "back.plan"
    code, out, err = gcs(capsys, v, "mission", "download", str(back))
    assert code == 0, out + err
    plain = {5: 0, 6: 3, 11: 10}
    expected = plan_items(src)
    for entry in expected:
        entry["frame"] = plain.get(entry["frame"], entry["frame"])
    assert plan_items(back) == expected
    assert [e["frame"] for e in plan_items(back)] == [plain.get(it.frame, it.frame)
                                                      for it in items]
    assert 3 in [e["frame"] for e in plan_items(back)]  # 3 stays 3 (PX4 answers it as 6)


@pytest.mark.parametrize("fmt,ext", [("wpl", "waypoints"), ("toml", "toml")])
def test_wpl_and_toml_round_trip_keep_every_frame(vehicles, capsys, tmp_path, fmt, ext):
    """The same for QGC WPL lines and TOML raw items, through PX4 (no home line)."""
    v = vehicles("px4")
    src = tmp_path / f"src.{ext}"
    src.write_text(format_mission(PX4_ONLY, fmt))
    assert gcs(capsys, v, "mission", "upload", str(src))[0] == 0
    assert [w[1] for w in v.wire] == [it.frame for it in PX4_ONLY]
    back = tmp_path / f"back.{ext}"
    assert gcs(capsys, v, "mission", "download", str(back))[0] == 0
    plain = [it._replace(frame={5: 0, 6: 3, 11: 10}.get(it.frame, it.frame))
             for it in PX4_ONLY]
    assert back.read_text() == format_mission(plain, fmt)
    assert [it.frame for it in parse_mission(back.read_text(), fmt)] == \
        [it.frame for it in plain]
