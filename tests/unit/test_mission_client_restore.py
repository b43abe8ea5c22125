"""An upload is atomic for the user (gcs/cli/missions.py, gcs/vehicle_link/mission_home.py): to an
ArduPilot-like vehicle whose upload is not atomic (it truncates its mission at
MISSION_COUNT and writes each item as it comes, as ArduPilot's GCS_MAVLink mission protocol
does), `gcs mission upload` reads the mission first and puts it back when an item is
refused, or says what the vehicle now holds; to PX4 nothing is read. A plan written for
another firmware says so and what was converted, and is refused (exit 2) where the
conversion is not exact. All over loopback UDP."""

from __future__ import annotations

import json
import math
import threading
from pathlib import Path

import pytest

from common.wire.mavlink import MAV, MAV_CMD_POSE_KEYFRAME
from common.wire.mission_items import HomePosition, MissionItem
from gcs.mission_files import read_mission
from gcs.vehicle_link.mission_home import after_refusal, describe_held, home_item
from tests.unit.scripted_autopilot import HOME, ScriptedAutopilot, gcs

M = MAV
pytestmark = pytest.mark.timeout(60)
PLAN = Path(__file__).resolve().parents[1] / "data" / "qgc_mission.plan"
NAN = math.nan


def key(items):
    return [tuple("nan" if isinstance(v, float) and math.isnan(v) else v
                  for v in it[1:3] + it[4:12]) for it in items]  # seq, current apart


class NonAtomicArduPilot(ScriptedAutopilot):
    """ArduPilot-like, non-atomic: MISSION_COUNT truncates the mission to the count, each
    item is written at its seq as it comes, a refused item leaves the ones before it.
    `refuse_later`: every upload after the first is refused at seq 1 (MAV_MISSION_ERROR)."""

    def __init__(self, refuse: dict[int, tuple[int, str]], refuse_later: bool = False,
                 kind: str = "ardupilot") -> None:
        self.counts: list[int] = []
        self.lists = 0
        self.refuse_later = refuse_later
        super().__init__(kind, refuse=refuse)

    def _handle(self, msg) -> None:
        kind = msg.get_type()
        if kind == "MISSION_REQUEST_LIST":
            self.lists += 1
        if kind == "MISSION_COUNT":
            self.counts.append(msg.count)
            self.mission = self.mission[:msg.count]
            self._upload, self._count = [], msg.count
            self._request(0)
            return
        super()._handle(msg)

    def _item(self, item: MissionItem) -> None:
        if self._upload is None or item.seq != len(self._upload):
            return
        refused = self.refuse.get(item.command)
        if self.refuse_later and len(self.counts) > 1 and item.seq >= 1:
            refused = (M.MAV_MISSION_ERROR, "")
        if refused is not None:
            self._upload = None
            self._send(M.MAVLink_mission_ack_message(255, 0, refused[0], 0))
            return
        self._upload.append(item)
        if item.seq < len(self.mission):
            self.mission[item.seq] = item
        else:
            self.mission.append(item)
        if len(self._upload) < self._count:
            self._request(len(self._upload))
            return
        self._upload = None
        self._send(M.MAVLink_mission_ack_message(255, 0, M.MAV_MISSION_ACCEPTED, 0))


def waypoint(seq: int, north_e7: int, alt: float, command: int = 16) -> MissionItem:
    return MissionItem(seq, 3, command, 0, 1, 0.0, 0.0, 0.0, NAN, -353632621 + north_e7,
                       1491652374, alt)


OLD = [home_item(HomePosition(*HOME)), *(waypoint(s, 100 * s, 20.0) for s in range(1, 12))]
NEW = [waypoint(s, -50 * s, 10.0) for s in range(9)]
NEW[2] = waypoint(2, -100, 10.0, MAV_CMD_POSE_KEYFRAME)  # plan item 3: refused


def plan_file(tmp_path: Path, items, firmware: int = 3, name: str = "new.plan") -> Path:
    """A QGC plan of `items` (frame, command, params as given), planned home HOME."""
    doc = json.loads(PLAN.read_text())
    doc["mission"]["firmwareType"] = firmware
    doc["mission"]["plannedHomePosition"] = list(HOME)
    doc["mission"]["items"] = [
        {"autoContinue": True, "command": it.command, "doJumpId": i + 1, "frame": it.frame,
         "type": "SimpleItem",
         "params": [it.param1, it.param2, it.param3, None, it.x / 1e7, it.y / 1e7, it.z]
         if it.frame != 1 else [0, 0, 0, None, it.x / 1e4, it.y / 1e4, it.z]}
        for i, it in enumerate(items)]
    path = tmp_path / name
    path.write_text(json.dumps(doc))
    return path


@pytest.fixture
def vehicles():
    made: list[ScriptedAutopilot] = []

    def make(cls=NonAtomicArduPilot, **kwargs):
        v = cls(**kwargs)
        made.append(v)
        return v

    yield make
    for v in made:
        v.close()




REFUSE = {MAV_CMD_POSE_KEYFRAME: (M.MAV_MISSION_UNSUPPORTED, "")}


def test_refused_upload_puts_the_old_mission_back(vehicles, capsys, tmp_path):
    """Given a vehicle holding home and 11 items that refuses plan item 3 of 9 after
    taking items 0-2 (and truncates to the new count), then the CLI reads the 12 items
    first, uploads them again after the refusal, says so, exits 1, and the vehicle holds
    exactly its old mission."""
    v = vehicles(refuse=REFUSE)
    v.mission = list(OLD)
    code, out, err = gcs(capsys, v, "mission", "upload", str(plan_file(tmp_path, NEW)))
    assert code == 1, out + err
    lines = out.splitlines()
    assert "upload of 9 items refused: MAV_MISSION_UNSUPPORTED: item 3 of 9" in lines
    assert ("vehicle refused item 3 of 9 (MAV_MISSION_UNSUPPORTED); restored the 12-item "
            "mission (home at seq 0 and 11 items) it held before") in lines, out
    assert v.lists == 1 and v.counts == [10, 12]
    assert key(v.mission) == key(OLD)


def test_a_failed_restore_says_what_the_vehicle_holds(vehicles, capsys, tmp_path):
    """Given the same vehicle that also refuses the restore at its seq 1, then the CLI
    says that putting the mission back failed and what the vehicle now holds, read back:
    home, new items 1-2, old items 3-9 (truncated to the new count of 10); exit 1."""
    v = vehicles(refuse=REFUSE, refuse_later=True)
    v.mission = list(OLD)
    code, out, err = gcs(capsys, v, "mission", "upload", str(plan_file(tmp_path, NEW)))
    assert code == 1, out + err
    assert ("vehicle refused item 3 of 9 (MAV_MISSION_UNSUPPORTED); putting back the "
            "12-item mission (home at seq 0 and 11 items) it held before failed: refused: "
            "MAV_MISSION_ERROR; the vehicle now holds home (seq 0), new items 1-2 and its "
            "old items 3-9") in out.splitlines(), out
    assert key(v.mission[1:3]) == key(NEW[:2]) and key(v.mission[3:]) == key(OLD[3:10])
    assert len(v.mission) == 10


def test_px4_is_atomic_nothing_read(vehicles, capsys, tmp_path):
    """To a PX4-like vehicle (atomic) the upload reads nothing first and restores nothing."""
    v = vehicles(refuse=REFUSE, kind="px4")
    code, out, _ = gcs(capsys, v, "mission", "upload",
                       str(plan_file(tmp_path, NEW, firmware=12)))
    assert code == 1 and "upload of 9 items refused" in out
    assert v.lists == 0 and v.counts == [9] and "restored" not in out


def test_what_ardupilot_holds_by_its_rule():
    """after_refusal follows ArduPilot: truncate at MISSION_COUNT, write as they come."""
    held = after_refusal(["old"] * 12, 10, 3, "new")
    assert held == ["new"] * 3 + ["old"] * 7
    assert describe_held(held, True) == "home (seq 0), new items 1-2 and its old items 3-9"
    assert after_refusal(["old"] * 2, 10, 4, "new") == ["new"] * 4
    assert describe_held(["new", "old", "x"], False) == \
        "new item 0, its old item 1 and item 2 of neither mission"


# ------------------------------------------------------------------ another firmware


def test_px4_plan_to_ardupilot_says_what_was_converted(vehicles, capsys):
    """QGC's plan for PX4 (firmwareType 12) to ArduPilot: one notice line naming both
    firmwares and the conversion, then the lines as before; exit 0."""
    v = vehicles(refuse={})
    code, out, err = gcs(capsys, v, "mission", "upload", str(PLAN))
    assert code == 0, out + err
    lines = out.splitlines()
    assert lines[0] == ("plan written for PX4 (firmwareType 12), the vehicle is ArduPilot "
                        "(3): converted: home at seq 0, the plan's items from seq 1")
    assert lines[1].startswith("home (seq 0): ") and lines[-1] == \
        "upload of 5 items: MAV_MISSION_ACCEPTED"
    assert key(v.mission[1:]) == key(read_mission(PLAN))


def test_ardupilot_plan_to_px4_says_what_was_converted(vehicles, capsys, tmp_path):
    v = vehicles(refuse={}, kind="px4")
    code, out, err = gcs(capsys, v, "mission", "upload", str(plan_file(tmp_path, NEW[:2])))
    assert code == 0, out + err
    assert out.splitlines() == [
        "plan written for ArduPilot (firmwareType 3), the vehicle is PX4 (12): converted: "
        "the planned home is not sent (the vehicle keeps home out of the mission), the items "
        "go from seq 0 as they are", "upload of 2 items: MAV_MISSION_ACCEPTED"]
    assert key(v.mission) == key(NEW[:2])


def test_inexact_conversion_is_exit_2_nothing_sent(vehicles, capsys, tmp_path):
    """A PX4 plan with a local-frame item to ArduPilot would go through the vehicle's
    home, rounded: exit 2 with the reason, no MISSION_COUNT sent. The same plan for
    ArduPilot converts as TOML missions do (no notice)."""
    local = MissionItem(1, 1, 16, 0, 1, 0.0, 0.0, 0.0, NAN, 100000, 0, -10.0)
    v = vehicles(refuse={})
    code, out, err = gcs(capsys, v, "mission", "upload",
                         str(plan_file(tmp_path, [NEW[0], local], firmware=12)))
    assert code == 2 and v.counts == [] and v.lists == 0, out + err
    assert "plan written for PX4 (firmwareType 12), the vehicle is ArduPilot (3): its " \
        "local-frame item(s) 2 would go in a global frame" in err
    code, out, err = gcs(capsys, v, "mission", "upload",
                         str(plan_file(tmp_path, [NEW[0], local], firmware=3)))
    assert code == 0 and "written for" not in out, out + err


class Unreadable(NonAtomicArduPilot):
    """Answers no MISSION_REQUEST_LIST: its mission cannot be read before an upload."""

    def _handle(self, msg) -> None:
        if msg.get_type() != "MISSION_REQUEST_LIST":
            super()._handle(msg)


def test_unreadable_mission_is_exit_1_nothing_sent(vehicles, capsys, tmp_path, monkeypatch):
    """Given an ArduPilot-like vehicle whose mission cannot be read, then the upload is
    exit 1 with the reason and no MISSION_COUNT is sent (nothing could be put back). (The
    vehicle is heard throughout: the download gives up at its ceiling, 3 s here, 30 s as
    shipped.)"""
    import gcs.vehicle_link.mission_client as client

    assert client.download.__kwdefaults__["ceiling_s"] == 30.0
    monkeypatch.setitem(client.download.__kwdefaults__, "ceiling_s", 3.0)
    v = vehicles(Unreadable, refuse=REFUSE)
    v.mission = list(OLD)
    code, out, err = gcs(capsys, v, "mission", "upload", str(plan_file(tmp_path, NEW)))
    assert code == 1 and v.counts == [] and key(v.mission) == key(OLD), out + err
    assert "reading the mission the vehicle holds (to put it back if the upload is " \
        "refused) failed: mission download from system 1: no answer to " \
        "MISSION_REQUEST_LIST" in err and "nothing uploaded" in err


class SlowChecker(ScriptedAutopilot):
    """PX4-like; it checks the whole mission for `check_s` after the last item before its
    MISSION_ACK (and answers a repeated last item by checking on)."""

    def __init__(self, check_s: float) -> None:
        self.check_s = check_s
        self._checked: list | None = None  # the mission its check accepted
        super().__init__("px4")

    def _item(self, item) -> None:
        if self._upload is not None and item.seq == self._count - 1 and \
                item.seq == len(self._upload):
            self._upload.append(item)
            mission, self._upload = self._upload, None
            threading.Timer(self.check_s, self._accept, (mission,)).start()
            return
        super()._item(item)

    def _unasked_item(self, item) -> None:
        if self._upload is None and self.mission != self._checked:
            return  # the last item again while it checks: it checks on
        super()._unasked_item(item)

    def _accept(self, mission) -> None:
        self.mission = self._checked = mission
        self._last_count = len(mission)
        self._send(M.MAVLink_mission_ack_message(255, 0, M.MAV_MISSION_ACCEPTED, 0))


def test_a_vehicle_that_checks_the_mission_before_its_ack_is_waited_for(tmp_path):
    """Given a vehicle that takes 3 s after the last item to check the mission, then the
    upload waits for its MISSION_ACK while the vehicle is heard (`gcs.vehicle_link.patience`)
    instead of giving up after the item retries (6 x 250 ms), and the vehicle holds the mission."""
    from gcs.vehicle_link.mission_client import upload_detailed
    from gcs.vehicle_link.session import Session

    v = SlowChecker(3.0)
    session = Session(v.url)
    try:
        session.wait_vehicle(timeout=5.0)
        items = [MissionItem(i, 1, 16, int(i == 0), 1, 0, 0, 0, 0, 0, 0, -2.0)
                 for i in range(3)]
        answer = upload_detailed(session.conn, session.target_system,
                                 session.target_component, items, timeout_s=0.25,
                                 send=session.send)
        assert answer.result == M.MAV_MISSION_ACCEPTED
        assert len(v.mission) == 3
    finally:
        session.close()
        v.close()
