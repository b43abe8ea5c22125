"""The ground station's mission client against answers of an earlier transaction (late
duplicates on a lossy link): they must never turn into a false success or a mission of the
wrong length. A scripted vehicle sends the stale answer right after the request, so each
case is deterministic."""

from __future__ import annotations

import math
import select
import threading
import time

import pytest

import common.wire.mavlink  # noqa: F401  (MAVLink 2 before mavutil)
from common.wire.mavlink import MAV, encoder, pack
from common.wire.mission_items import MissionItem, local_xy
from gcs.vehicle_link.mission_client import MissionError, download, upload

from .test_mission_client import VEHICLE, UdpVehicle, same_items

M = MAV


def _mission(n: int, z: float = -2.0) -> list[MissionItem]:
    return [MissionItem(i, M.MAV_FRAME_LOCAL_NED, M.MAV_CMD_NAV_WAYPOINT, int(i == 0), 1, 0.0,
                        0.0, 0.0, math.nan, local_xy(i), local_xy(-i), z) for i in range(n)]


class StaleVehicle(UdpVehicle):
    """A UdpVehicle that answers the first message of `trigger` type with `stale` (encoded
    as the vehicle) before handling it."""

    def __init__(self, trigger: str, stale, **kwargs) -> None:
        self.trigger, self.stale, self.fired = trigger, stale, False
        super().__init__(**kwargs)
        handle = self.server.handle

        def handle_with_stale(msg, now):
            if msg.get_type() == self.trigger and not self.fired:
                self.fired = True
                self._stale_out.append(self.stale)
            return [*self._stale_out_pop(), *handle(msg, now)]

        self._stale_out: list = []
        self.server.handle = handle_with_stale

    def _stale_out_pop(self):
        out, self._stale_out = self._stale_out, []
        return out


@pytest.fixture
def connect():
    from pymavlink import mavutil

    made = []

    def make(vehicle):
        conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{vehicle.port}", source_system=255,
                                          source_component=M.MAV_COMP_ID_MISSIONPLANNER,
                                          dialect="common")
        made.append((vehicle, conn))
        return conn

    yield make
    for vehicle, conn in made:
        conn.close()
        vehicle.close()


def test_a_stale_accepted_ack_is_not_taken_for_the_uploads(connect):
    """Before: the client returned MAV_MISSION_ACCEPTED on the stale ACK that arrived right
    after its MISSION_COUNT, while the vehicle had not received a single item."""
    ack = M.MAVLink_mission_ack_message(255, M.MAV_COMP_ID_MISSIONPLANNER,
                                        M.MAV_MISSION_ACCEPTED, 0)
    vehicle = StaleVehicle("MISSION_COUNT", ack)
    conn = connect(vehicle)
    items = _mission(3)
    assert upload(conn, *VEHICLE, items) == M.MAV_MISSION_ACCEPTED
    assert vehicle.fired
    assert same_items(vehicle.server.mission, items)


def test_a_stale_count_never_gives_a_shorter_mission(connect):
    """Before: a late MISSION_COUNT of an earlier download (here 2 for a mission of 4) was
    taken, and download returned the first 2 items as the whole mission."""
    count = M.MAVLink_mission_count_message(255, M.MAV_COMP_ID_MISSIONPLANNER, 2, 0)
    vehicle = StaleVehicle("MISSION_REQUEST_LIST", count)
    conn = connect(vehicle)
    items = _mission(4)
    assert upload(conn, *VEHICLE, items) == M.MAV_MISSION_ACCEPTED
    with pytest.raises(MissionError, match="MISSION_COUNT 2, then 4"):
        download(conn, *VEHICLE)
    assert same_items(download(conn, *VEHICLE), items)  # the next try is clean


def test_input_waiting_before_a_transaction_is_dropped(connect):
    """A stale ACK already queued on the connection when upload starts is not read as its
    answer, nor a stale count as a download's."""
    vehicle = UdpVehicle()
    conn = connect(vehicle)
    items = _mission(2)
    assert upload(conn, *VEHICLE, items) == M.MAV_MISSION_ACCEPTED
    mav = encoder(*VEHICLE)
    port = conn.port.getsockname()[1]
    vehicle.sock.sendto(pack(mav, M.MAVLink_mission_ack_message(
        255, M.MAV_COMP_ID_MISSIONPLANNER, M.MAV_MISSION_INVALID_PARAM7, 0)),
        ("127.0.0.1", port))
    vehicle.sock.sendto(pack(mav, M.MAVLink_mission_count_message(
        255, M.MAV_COMP_ID_MISSIONPLANNER, 7, 0)), ("127.0.0.1", port))

    time.sleep(0.05)
    longer = _mission(3, z=-4.0)
    assert upload(conn, *VEHICLE, longer) == M.MAV_MISSION_ACCEPTED
    assert same_items(download(conn, *VEHICLE), longer)


class SlowVehicle(UdpVehicle):
    """A UdpVehicle that takes `delay` seconds over each answer (a slow link)."""

    def __init__(self, delay: float, **kwargs) -> None:
        super().__init__(**kwargs)
        handle = self.server.handle

        def slow(msg, now):
            time.sleep(delay)
            return handle(msg, now)

        self.server.handle = slow


def test_a_late_duplicate_of_an_earlier_answer_is_dropped_before_the_next_upload(connect):
    """The failure seen in tests/sitl/test_lossy_missions.py: a copy of the previous
    upload's MISSION_ACK, held back by the link a few ms, arrived after the next upload had
    begun; the client returned that result although the vehicle took the new mission. The
    client now lets such answers pass (SETTLE_S, 50 ms, without one) before it starts: one
    already waiting when the upload starts, and one that comes within the settling time
    (a settling time of 1 s here, so that a busy machine's late timer still falls in it)."""
    vehicle = SlowVehicle(0.01)
    conn = connect(vehicle)
    stale = pack(encoder(*VEHICLE), M.MAVLink_mission_ack_message(
        255, M.MAV_COMP_ID_MISSIONPLANNER, M.MAV_MISSION_OPERATION_CANCELLED, 0))

    def send_stale() -> None:  # to the client's port, bound by its first send
        vehicle.sock.sendto(stale, ("127.0.0.1", conn.port.getsockname()[1]))

    def arrived(timeout_s: float = 5.0) -> None:
        """Until the stale answer waits in the client's socket."""
        assert select.select([conn.port], [], [], timeout_s)[0], "the stale answer is lost"

    assert upload(conn, *VEHICLE, _mission(1)) == M.MAV_MISSION_ACCEPTED  # the previous one
    items = _mission(3)
    send_stale()
    arrived()
    assert upload(conn, *VEHICLE, items) == M.MAV_MISSION_ACCEPTED
    assert same_items(vehicle.server.mission, items)
    timer = threading.Timer(0.02, send_stale)
    timer.start()
    items = _mission(2)
    assert upload(conn, *VEHICLE, items, settle_s=1.0) == M.MAV_MISSION_ACCEPTED
    timer.join()
    assert same_items(vehicle.server.mission, items)
    # without the settling time, the very same stale answer is taken for the upload's
    send_stale()
    arrived()
    assert upload(conn, *VEHICLE, _mission(3, z=-5.0), settle_s=0.0) == \
        M.MAV_MISSION_OPERATION_CANCELLED
    assert same_items(vehicle.server.mission, items)
