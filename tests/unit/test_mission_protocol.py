"""Vehicle side of the mission protocol (fcu/edge/mission_protocol.py), driven with pymavlink
messages that go through the MAVLink 2 codec both ways, as on a link."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from common.config.scenario import load_scenario, load_vehicle
from common.wire.mavlink import (
    MAV,
    MAV_CMD_FIGURE_EIGHT,
    MAV_CMD_POSE_KEYFRAME,
    encoder,
    pack,
    parser,
)
from common.wire.mission_items import MissionItem, local_xy
from fcu.edge.mission_protocol import MissionServer, statustext_chunks
from fcu.mission.executor import MissionExecutor
from fcu.mission.limits import MissionLimits
from fcu.mission.validation import check_mission
from gcs.run.scenario_mission import scenario_mission

M = MAV
ROOT = Path(__file__).resolve().parents[2]
GCS = (255, M.MAV_COMP_ID_MISSIONPLANNER)
OTHER_GCS = (254, M.MAV_COMP_ID_MISSIONPLANNER)
VEHICLE = (1, M.MAV_COMP_ID_AUTOPILOT1)
MISSION = M.MAV_MISSION_TYPE_MISSION
NAN = math.nan


def case1() -> list[MissionItem]:
    return scenario_mission(load_scenario(ROOT / "config/scenarios/case1_figure8.toml"))


def waypoints(n: int, z: float = -3.0) -> list[MissionItem]:
    return [MissionItem(i, M.MAV_FRAME_LOCAL_NED, M.MAV_CMD_NAV_WAYPOINT, int(i == 0), 1,
                        0.5 * i, 0.0, 0.0, NAN, local_xy(i), local_xy(-i), z)
            for i in range(n)]


def same_items(a, b) -> bool:
    """MissionItem sequences equal, NaN equal to NaN."""
    def key(it):
        return tuple("nan" if isinstance(v, float) and math.isnan(v) else v for v in it)
    return [key(x) for x in a] == [key(x) for x in b]


def through_wire(msg, src):
    """msg as the receiver decodes it from a MAVLink 2 frame sent by `src`."""
    return parser().decode(bytearray(pack(encoder(*src), msg)))


class Link:
    """A GCS talking to one MissionServer; every message in both directions is encoded."""

    def __init__(self, server: MissionServer, src=GCS) -> None:
        self.server = server
        self.src = src
        self.now = 0.0
        self.changes: list[tuple[MissionItem, ...]] = []
        self.texts: list = []  # STATUSTEXT (broadcast), kept apart from the replies

    def _out(self, replies):
        decoded = [through_wire(r, VEHICLE) for r in replies]
        texts = [r for r in decoded if r.get_type() == "STATUSTEXT"]
        self.texts += texts
        decoded = [r for r in decoded if r.get_type() != "STATUSTEXT"]
        for r in decoded:  # every other reply is addressed to us
            assert (r.target_system, r.target_component) == self.src, r
        return decoded

    def send(self, msg):
        return self._out(self.server.handle(through_wire(msg, self.src), self.now))

    def tick(self, dt: float):
        self.now += dt
        return self._out(self.server.tick(self.now))

    # Messages from this GCS.
    def count(self, n: int, mission_type: int = MISSION):
        return self.send(M.MAVLink_mission_count_message(*VEHICLE, n, mission_type))

    def item(self, it: MissionItem, legacy: bool = False):
        if legacy:
            return self.send(M.MAVLink_mission_item_message(
                *VEHICLE, it.seq, it.frame, it.command, it.current, it.autocontinue, it.param1,
                it.param2, it.param3, it.param4, it.x_m, it.y_m, it.z, MISSION))
        return self.send(M.MAVLink_mission_item_int_message(
            *VEHICLE, it.seq, it.frame, it.command, it.current, it.autocontinue, it.param1,
            it.param2, it.param3, it.param4, it.x, it.y, it.z, MISSION))

    def upload(self, items, legacy: bool = False):
        """A loss-free upload; the final MISSION_ACK."""
        replies = self.count(len(items))
        while True:
            (r,) = replies
            if r.get_type() == "MISSION_ACK":
                return r
            assert r.get_type() == "MISSION_REQUEST_INT" and r.mission_type == MISSION
            replies = self.item(items[r.seq], legacy)

    def download(self) -> list[MissionItem]:
        (c,) = self.send(M.MAVLink_mission_request_list_message(*VEHICLE, MISSION))
        assert c.get_type() == "MISSION_COUNT"
        out = []
        for seq in range(c.count):
            (r,) = self.send(M.MAVLink_mission_request_int_message(*VEHICLE, seq, MISSION))
            assert r.get_type() == "MISSION_ITEM_INT" and r.seq == seq
            out.append(MissionItem(r.seq, r.frame, r.command, r.current, r.autocontinue,
                                   r.param1, r.param2, r.param3, r.param4, r.x, r.y, r.z,
                                   r.mission_type))
        assert self.send(M.MAVLink_mission_ack_message(*VEHICLE, M.MAV_MISSION_ACCEPTED,
                                                       MISSION)) == []
        return out


@pytest.fixture
def server() -> MissionServer:
    return MissionServer(*VEHICLE, MissionLimits())


@pytest.fixture
def link(server) -> Link:
    lk = Link(server)
    server.on_mission_changed = lk.changes.append
    return lk


def kinds(replies) -> list[tuple[str, int]]:
    return [(r.get_type(), r.seq if hasattr(r, "seq") else r.type) for r in replies]


# ----------------------------------------------------------------------------------------
# Round trip
# ----------------------------------------------------------------------------------------


def test_upload_download_round_trip(server, link):
    """Given the Case I mission, when uploaded and downloaded, then the vehicle accepts it,
    stores it atomically (one change callback), and gives the same items back."""
    items = case1()
    ack = link.upload(items)
    assert ack.type == M.MAV_MISSION_ACCEPTED and ack.mission_type == MISSION
    assert same_items(server.mission, items)
    assert len(link.changes) == 1 and same_items(link.changes[0], items)
    assert server.version == 1
    assert same_items(link.download(), items)


def test_legacy_mission_item_and_request(server, link):
    """Given legacy MISSION_ITEM (float metres) items, then they are stored as int 1e-4 m;
    a legacy MISSION_REQUEST is answered with MISSION_ITEM_INT."""
    items = waypoints(3)
    assert link.upload(items, legacy=True).type == M.MAV_MISSION_ACCEPTED
    assert same_items(server.mission, items)
    (r,) = link.send(M.MAVLink_mission_request_message(*VEHICLE, 2, MISSION))
    assert r.get_type() == "MISSION_ITEM_INT" and r.x == local_xy(2.0) and r.y == local_xy(-2)


def test_legacy_item_with_unusable_x_is_refused(server, link):
    """Given a legacy MISSION_ITEM whose float x is NaN or beyond int32 in 1e-4 m, then the
    upload ends with INVALID_PARAM5_X / 6_Y (never an exception) and nothing changes."""
    for x, y, result in ((NAN, 0.0, M.MAV_MISSION_INVALID_PARAM5_X),
                         (0.0, 3e5, M.MAV_MISSION_INVALID_PARAM6_Y)):
        link.count(1)
        (ack,) = link.send(M.MAVLink_mission_item_message(
            *VEHICLE, 0, M.MAV_FRAME_LOCAL_NED, M.MAV_CMD_NAV_WAYPOINT, 1, 1, 0.0, 0.0, 0.0,
            NAN, x, y, -2.0, MISSION))
        assert ack.get_type() == "MISSION_ACK" and ack.type == result
    assert server.mission == () and link.changes == []


def test_version_changes_on_every_accepted_change(server, link):
    """Given uploads and clears, then `version` changes on each accepted change only."""
    link.upload(waypoints(2))
    v1 = server.version
    link.upload(waypoints(2, z=NAN))  # refused
    assert server.version == v1
    link.upload(waypoints(3))
    v2 = server.version
    (ack,) = link.send(M.MAVLink_mission_clear_all_message(*VEHICLE, MISSION))
    assert ack.type == M.MAV_MISSION_ACCEPTED
    assert len({0, v1, v2, server.version}) == 4
    assert server.mission == () and link.changes[-1] == ()


# ----------------------------------------------------------------------------------------
# Loss, duplicates, reordering
# ----------------------------------------------------------------------------------------


def test_lost_request_is_re_requested_after_the_item_timeout(server, link):
    """Given a MISSION_REQUEST_INT that never arrives (not answered), then the vehicle asks
    again after item_timeout_s, not before, and the upload completes."""
    items = waypoints(3)
    assert kinds(link.count(3)) == [("MISSION_REQUEST_INT", 0)]
    assert link.tick(0.2) == []
    assert kinds(link.tick(0.06)) == [("MISSION_REQUEST_INT", 0)]  # 0.26 s after
    assert kinds(link.item(items[0])) == [("MISSION_REQUEST_INT", 1)]
    # Item 1 lost on the way: re-requested, twice.
    assert kinds(link.tick(0.3)) == [("MISSION_REQUEST_INT", 1)]
    assert kinds(link.tick(0.3)) == [("MISSION_REQUEST_INT", 1)]
    assert kinds(link.item(items[1])) == [("MISSION_REQUEST_INT", 2)]
    (ack,) = link.item(items[2])
    assert ack.type == M.MAV_MISSION_ACCEPTED and same_items(server.mission, items)


def test_duplicates_and_reordering_re_request_the_expected_item(server, link):
    """Given a duplicate item and an item ahead of its turn, then the vehicle re-requests
    the expected seq (no error) and stores the items in order."""
    items = waypoints(4)
    link.count(4)
    assert kinds(link.item(items[0])) == [("MISSION_REQUEST_INT", 1)]
    assert kinds(link.item(items[0])) == [("MISSION_REQUEST_INT", 1)]  # duplicate
    assert kinds(link.item(items[2])) == [("MISSION_REQUEST_INT", 1)]  # ahead
    assert kinds(link.item(items[1])) == [("MISSION_REQUEST_INT", 2)]
    assert kinds(link.item(items[3])) == [("MISSION_REQUEST_INT", 2)]  # ahead
    assert kinds(link.item(items[2])) == [("MISSION_REQUEST_INT", 3)]
    (ack,) = link.item(items[3])
    assert ack.type == M.MAV_MISSION_ACCEPTED and same_items(server.mission, items)
    assert len(link.changes) == 1


def test_lost_final_ack_is_sent_again(server, link):
    """Given the final MISSION_ACK lost, when the GCS sends the last item again, then the
    same ACK comes again and the mission is not replaced twice."""
    items = waypoints(2)
    link.upload(items)
    (ack,) = link.item(items[1])
    assert ack.get_type() == "MISSION_ACK" and ack.type == M.MAV_MISSION_ACCEPTED
    assert len(link.changes) == 1 and server.version == 1


def test_silent_gcs_cancels_and_keeps_the_old_mission(server, link):
    """Given an upload whose items stop coming, then the vehicle re-requests `retries` times,
    then answers MISSION_ACK OPERATION_CANCELLED and keeps the old mission."""
    old = waypoints(2)
    link.upload(old)
    new = waypoints(3, z=-7.0)
    link.count(3)
    link.item(new[0])
    for _ in range(5):
        assert kinds(link.tick(0.25)) == [("MISSION_REQUEST_INT", 1)]
    (ack,) = link.tick(0.25)
    assert ack.get_type() == "MISSION_ACK"
    assert ack.type == M.MAV_MISSION_OPERATION_CANCELLED
    assert link.tick(10.0) == [] and not server.uploading
    assert same_items(server.mission, old) and len(link.changes) == 1
    # A late item of the cancelled upload is told so again.
    (ack,) = link.item(new[1])
    assert ack.type == M.MAV_MISSION_OPERATION_CANCELLED


def test_gcs_cancel_and_restart(server, link):
    """Given a MISSION_ACK from the uploading GCS mid-upload, then the upload is dropped;
    given a new MISSION_COUNT mid-upload, then the transaction restarts at item 0."""
    old = waypoints(2)
    link.upload(old)
    link.count(3)
    link.item(waypoints(3)[0])
    assert link.send(M.MAVLink_mission_ack_message(
        *VEHICLE, M.MAV_MISSION_OPERATION_CANCELLED, MISSION)) == []
    assert not server.uploading and same_items(server.mission, old)
    link.count(3)
    link.item(waypoints(3)[0])
    assert kinds(link.count(2)) == [("MISSION_REQUEST_INT", 0)]
    new = waypoints(2, z=-9.0)
    assert kinds(link.item(new[0])) == [("MISSION_REQUEST_INT", 1)]
    (ack,) = link.item(new[1])
    assert ack.type == M.MAV_MISSION_ACCEPTED and same_items(server.mission, new)


def test_second_gcs_is_denied_while_one_uploads(server, link):
    """Given an upload in progress, then another GCS's MISSION_COUNT is DENIED and the first
    upload carries on."""
    other = Link(server, OTHER_GCS)
    link.count(2)
    (ack,) = other.count(1)
    assert ack.type == M.MAV_MISSION_DENIED
    items = waypoints(2)
    link.item(items[0])
    assert other.item(items[1]) == []  # not its transaction
    assert link.item(items[1])[0].type == M.MAV_MISSION_ACCEPTED


# ----------------------------------------------------------------------------------------
# Refusals
# ----------------------------------------------------------------------------------------


def test_no_space(server, link):
    """Given more items than max_items, then MISSION_ACK NO_SPACE at once."""
    server.limits = MissionLimits(max_items=3)
    link.upload(waypoints(2))
    (ack,) = link.count(4)
    assert ack.get_type() == "MISSION_ACK" and ack.type == M.MAV_MISSION_NO_SPACE
    assert not server.uploading and len(server.mission) == 2


@pytest.mark.parametrize("mission_type", [M.MAV_MISSION_TYPE_FENCE, M.MAV_MISSION_TYPE_RALLY])
def test_other_plan_types_are_unsupported(server, link, mission_type):
    """Given fence or rally messages, then MISSION_ACK UNSUPPORTED with that type, and the
    mission is untouched; MISSION_CLEAR_ALL for all types clears and is accepted."""
    link.upload(waypoints(2))
    for msg in (M.MAVLink_mission_count_message(*VEHICLE, 3, mission_type),
                M.MAVLink_mission_request_list_message(*VEHICLE, mission_type),
                M.MAVLink_mission_request_int_message(*VEHICLE, 0, mission_type),
                M.MAVLink_mission_clear_all_message(*VEHICLE, mission_type)):
        (ack,) = link.send(msg)
        assert ack.get_type() == "MISSION_ACK", msg
        assert (ack.type, ack.mission_type) == (M.MAV_MISSION_UNSUPPORTED, mission_type)
    assert len(server.mission) == 2
    (ack,) = link.send(M.MAVLink_mission_clear_all_message(*VEHICLE, M.MAV_MISSION_TYPE_ALL))
    assert ack.type == M.MAV_MISSION_ACCEPTED and server.mission == ()


@pytest.mark.parametrize(("change", "result"), [
    ({"z": NAN}, M.MAV_MISSION_INVALID_PARAM7),
    ({"param1": -1.0}, M.MAV_MISSION_INVALID_PARAM1),
    ({"command": M.MAV_CMD_DO_SET_SERVO}, M.MAV_MISSION_UNSUPPORTED),
    ({"frame": M.MAV_FRAME_GLOBAL_INT}, M.MAV_MISSION_UNSUPPORTED_FRAME),
    ({"x": local_xy(5000.0)}, M.MAV_MISSION_DENIED),
])
def test_invalid_item_keeps_the_old_mission(server, link, change, result):
    """Given a mission with one invalid item, then the final ACK names the problem and the
    old mission stays (no change callback)."""
    old = case1()
    link.upload(old)
    new = waypoints(3)
    new[1] = new[1]._replace(**change)
    ack = link.upload(new)
    assert ack.type == result
    assert same_items(server.mission, old) and len(link.changes) == 1


def test_count_zero_clears(server, link):
    """Given MISSION_COUNT 0, then the mission is cleared and the ACK is ACCEPTED."""
    link.upload(waypoints(2))
    (ack,) = link.count(0)
    assert ack.type == M.MAV_MISSION_ACCEPTED and server.mission == ()
    assert link.changes[-1] == ()


# ----------------------------------------------------------------------------------------
# Download details, current item, addressing
# ----------------------------------------------------------------------------------------


def test_download_out_of_range_and_current_flag(server, link):
    """Given a request beyond the mission, then ACK INVALID_SEQUENCE; items carry current = 1
    on the current seq only, which MISSION_SET_CURRENT moves through the callback."""
    link.upload(waypoints(3))
    (ack,) = link.send(M.MAVLink_mission_request_int_message(*VEHICLE, 3, MISSION))
    assert ack.get_type() == "MISSION_ACK" and ack.type == M.MAV_MISSION_INVALID_SEQUENCE
    asked: list[int] = []
    answer = [True]

    def on_set_current(seq: int) -> bool:
        asked.append(seq)
        return answer[0]

    server.on_set_current = on_set_current
    assert link.send(M.MAVLink_mission_set_current_message(*VEHICLE, 2)) == []
    assert [it.current for it in link.download()] == [0, 0, 1]
    answer[0] = False
    link.send(M.MAVLink_mission_set_current_message(*VEHICLE, 1))  # refused by the vehicle
    link.send(M.MAVLink_mission_set_current_message(*VEHICLE, 7))  # no such item
    assert asked == [2, 1] and server.current_seq == 2


def test_empty_download_and_foreign_messages(server, link):
    """Given no mission, then MISSION_COUNT 0; messages for another system or component
    are ignored."""
    (c,) = link.send(M.MAVLink_mission_request_list_message(*VEHICLE, MISSION))
    assert c.count == 0
    assert link.send(M.MAVLink_mission_count_message(7, VEHICLE[1], 2, MISSION)) == []
    assert link.send(M.MAVLink_mission_count_message(VEHICLE[0], 42, 2, MISSION)) == []
    assert not server.uploading
    assert kinds(link.send(M.MAVLink_mission_count_message(0, 0, 1, MISSION))) == [
        ("MISSION_REQUEST_INT", 0)]  # broadcast is for us


def test_case1_through_the_wire_flies_the_same(server, link):
    """Given Case I uploaded through the codec (float32 params), then the stored mission
    executes to the same plan as the items built in memory."""
    items = case1()
    link.upload(items)
    a, b = MissionExecutor(items, server.limits), MissionExecutor(server.mission,
                                                                  server.limits)
    for ex in (a, b):
        ex.start(0.0, (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))
    assert a.schedule == b.schedule
    for t in (3.0, 15.0, 77.7, 150.0):
        assert a.sample(t) == b.sample(t)
    assert server.mission[2].command == MAV_CMD_FIGURE_EIGHT


# ----------------------------------------------------------------------------------------
# Refusals with a reason: STATUSTEXT just before the MISSION_ACK
# ----------------------------------------------------------------------------------------


def _too_fast_keyframe() -> list[MissionItem]:
    return [MissionItem(0, M.MAV_FRAME_LOCAL_NED, M.MAV_CMD_NAV_TAKEOFF, 1, 1, 0.0, 0.0, 0.0,
                        NAN, 0, 0, -3.0),
            MissionItem(1, M.MAV_FRAME_LOCAL_NED, MAV_CMD_POSE_KEYFRAME, 0, 1, 0.5, 0.0, 0.0,
                        0.0, local_xy(2.0), 0, -3.0)]


def test_refusal_reason_comes_as_statustext_before_the_ack():
    """Given a vehicle with its airframe and a keyframe it cannot fly in the time given, then
    the last item is answered with the reason as STATUSTEXT (WARNING, chunks of at most 50
    characters, one id, chunk_seq 0, 1, ...), then MISSION_ACK DENIED; the old mission
    stays. The final item sent again gets the same answer again."""
    vehicle = load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml")
    server = MissionServer(*VEHICLE, MissionLimits(vehicle=vehicle))
    link = Link(server)
    old = case1()
    assert link.upload(old).type == M.MAV_MISSION_ACCEPTED and link.texts == []
    items = _too_fast_keyframe()
    assert kinds(link.count(2)) == [("MISSION_REQUEST_INT", 0)]
    link.item(items[0])
    raw = server.handle(through_wire(M.MAVLink_mission_item_int_message(
        *VEHICLE, 1, items[1].frame, items[1].command, 0, 1, *items[1][5:12], MISSION), GCS),
        link.now)
    replies = [through_wire(r, VEHICLE) for r in raw]
    *texts, ack = replies
    assert ack.get_type() == "MISSION_ACK" and ack.type == M.MAV_MISSION_DENIED
    assert len(texts) == 2 and all(t.get_type() == "STATUSTEXT" for t in texts)
    assert all(t.severity == M.MAV_SEVERITY_WARNING for t in texts)
    assert [t.chunk_seq for t in texts] == [0, 1] and texts[0].id == texts[1].id != 0
    assert len(texts[0].text) == 50 and len(texts[1].text) < 50
    reason = " ".join("".join(t.text for t in texts).split())
    assert reason == check_mission(items, server.limits).reason
    assert reason.startswith("item 1: tilt servo ") and "lengthen p1 to" in reason
    assert same_items(server.mission, old)
    again = [through_wire(r, VEHICLE) for r in server.handle(through_wire(
        M.MAVLink_mission_item_int_message(*VEHICLE, 1, items[1].frame, items[1].command, 0,
                                           1, *items[1][5:12], MISSION), GCS), link.now)]
    assert [m.get_type() for m in again] == ["STATUSTEXT", "STATUSTEXT", "MISSION_ACK"]
    assert [m.text for m in again[:2]] == [t.text for t in texts]


def _said(link) -> str:
    """The STATUSTEXT the link heard, chunks put back together."""
    return " ".join("".join(t.text for t in link.texts).split())


@pytest.mark.parametrize(("change", "result", "reason"), [
    ({"z": NAN}, M.MAV_MISSION_INVALID_PARAM7, "item 1: z nan: must be a finite number"),
    ({"command": M.MAV_CMD_DO_SET_SERVO}, M.MAV_MISSION_UNSUPPORTED,
     "item 1: command 183 (MAV_CMD_DO_SET_SERVO) is not supported"),
    ({"frame": M.MAV_FRAME_BODY_FRD}, M.MAV_MISSION_UNSUPPORTED_FRAME,
     "item 1: frame 12 (MAV_FRAME_BODY_FRD) is not supported (local NED, or global with an "
     "altitude)"),
])
def test_every_refusal_says_why_before_the_ack(server, link, change, result, reason):
    """Given a mission refused for an item, then the STATUSTEXT before the MISSION_ACK names
    the item and what is wrong with it, whatever the result."""
    items = waypoints(3)
    items[1] = items[1]._replace(**change)
    assert link.upload(items).type == result
    assert _said(link) == reason
    assert reason == check_mission(items, server.limits).reason


def test_no_space_says_the_limit(server, link):
    """Given a MISSION_COUNT above the limit, then the STATUSTEXT before NO_SPACE says the
    count and the limit."""
    server.limits = MissionLimits(max_items=500)
    (ack,) = link.count(501)
    assert ack.type == M.MAV_MISSION_NO_SPACE
    assert _said(link) == "501 items: the vehicle holds at most 500"


@pytest.mark.parametrize("text", [
    "short",
    "item 3: needs 1903 rad/s > 1445 (85% of 1700): lengthen p1 to 0.87 s",
    "word " * 30,
    "x" * 120,
])
def test_statustext_chunks(text):
    """Given a text, then its chunks are at most 50 characters, all but the last exactly 50
    and the last shorter (MAVLink 2 reassembly), and they read back as the text."""
    chunks = statustext_chunks(text)
    assert all(len(c) == 50 for c in chunks[:-1]) and len(chunks[-1]) < 50
    joined = " ".join("".join(chunks).split())
    assert joined.replace(" ", "") == text.replace(" ", "")
    if " " in text.strip():
        assert joined == " ".join(text.split())
