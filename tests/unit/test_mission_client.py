"""Ground-station mission client (gcs/vehicle_link/mission_client.py) against a MissionServer behind
a loopback UDP socket, served by a small loop in a thread; optionally losing replies."""

from __future__ import annotations

import math
import random
import select
import socket
import threading
import time
from pathlib import Path

import pytest

import common.wire.mavlink  # noqa: F401  (MAVLink 2 before mavutil)
from common.config.scenario import load_scenario, load_vehicle
from common.wire.mavlink import MAV, MAV_CMD_POSE_KEYFRAME, encoder, pack, parser
from common.wire.mission_items import MissionItem, local_xy
from fcu.edge.mission_protocol import MissionServer, statustext_chunks
from fcu.mission.limits import MissionLimits
from fcu.mission.validation import check_mission
from gcs.run.scenario_mission import scenario_mission
from gcs.vehicle_link.mission_client import (
    MissionError,
    UploadResult,
    clear,
    download,
    upload,
    upload_detailed,
)
from gcs.vehicle_link.status_texts import StatusTexts

M = MAV
ROOT = Path(__file__).resolve().parents[2]
VEHICLE = (1, M.MAV_COMP_ID_AUTOPILOT1)
NAN = math.nan


class UdpVehicle:
    """A MissionServer on 127.0.0.1:<free port>; drops each reply with probability `drop`
    (seeded). Ticks the server every 10 ms and, as a vehicle does, sends a HEARTBEAT each
    second once it has heard the station (never dropped: the station then waits on a
    vehicle it knows is alive, however the drops fall)."""

    def __init__(self, drop: float = 0.0, seed: int = 0,
                 limits: MissionLimits | None = None) -> None:
        self.server = MissionServer(*VEHICLE, limits or MissionLimits())
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.mav = encoder(*VEHICLE)
        self.parser = parser()
        self.rng = random.Random(seed)
        self.drop = drop
        self.sent = self.dropped = 0
        self.errors: list[BaseException] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="udp-vehicle", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        peer = None
        heartbeat_due = 0.0
        try:
            while not self._stop.is_set():
                readable, _, _ = select.select([self.sock], [], [], 0.01)
                now = time.monotonic()
                if peer is not None and now >= heartbeat_due:
                    self.sock.sendto(pack(self.mav, M.MAVLink_heartbeat_message(
                        M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_PX4, 0, 0,
                        M.MAV_STATE_STANDBY, 3)), peer)
                    heartbeat_due = now + 1.0
                replies = []
                if readable:
                    data, peer = self.sock.recvfrom(65535)
                    for msg in self.parser.parse_buffer(data) or []:
                        if msg.get_type() != "BAD_DATA":
                            replies += self.server.handle(msg, now)
                replies += self.server.tick(now)
                for reply in replies:
                    if self.rng.random() < self.drop:
                        self.dropped += 1
                        continue
                    self.sock.sendto(pack(self.mav, reply), peer)
                    self.sent += 1
        except BaseException as exc:  # surfaced by close()
            self.errors.append(exc)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        self.sock.close()
        assert not self._thread.is_alive()
        assert not self.errors, self.errors


@pytest.fixture
def vehicle_factory():
    made: list[tuple[UdpVehicle, object]] = []

    from pymavlink import mavutil  # after common.wire.mavlink has pinned MAVLink 2

    def make(**kwargs):
        vehicle = UdpVehicle(**kwargs)
        conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{vehicle.port}",
                                          source_system=255,
                                          source_component=M.MAV_COMP_ID_MISSIONPLANNER,
                                          dialect="common")
        made.append((vehicle, conn))
        return vehicle, conn

    yield make
    for vehicle, conn in made:
        conn.close()
        vehicle.close()


def same_items(a, b) -> bool:
    def key(it):
        return tuple("nan" if isinstance(v, float) and math.isnan(v) else v for v in it)
    return [key(x) for x in a] == [key(x) for x in b]


def case1_and_more() -> list[MissionItem]:
    items = scenario_mission(load_scenario(ROOT / "config/scenarios/case1_figure8.toml"))
    extra = [MissionItem(0, M.MAV_FRAME_LOCAL_NED, M.MAV_CMD_NAV_WAYPOINT, 0, 1, 1.0, 0.0, 0.0,
                         45.0 * k, local_xy(0.5 * k), local_xy(-1.25 * k), -5.0 - 0.25 * k)
             for k in range(6)]
    land = MissionItem(0, M.MAV_FRAME_LOCAL_NED, M.MAV_CMD_NAV_LAND, 0, 1, 0.0, 0.0, 0.0, NAN,
                       0, 0, 0.0)
    return [it.with_seq(i) for i, it in enumerate([*items, *extra, land])]


def test_round_trip_and_clear(vehicle_factory):
    """Given a vehicle on loopback UDP, when the Case I mission is uploaded, downloaded and
    cleared, then it is accepted, comes back equal, and is gone after the clear; progress
    is reported up to (n, n)."""
    vehicle, conn = vehicle_factory()
    items = scenario_mission(load_scenario(ROOT / "config/scenarios/case1_figure8.toml"))
    seen: list[tuple[int, int]] = []
    result = upload(conn, *VEHICLE, items, progress=lambda d, n: seen.append((d, n)))
    assert result == M.MAV_MISSION_ACCEPTED
    assert seen[-1] == (4, 4) and [d for d, _ in seen] == sorted(d for d, _ in seen)
    assert same_items(vehicle.server.mission, items)
    got: list[tuple[int, int]] = []
    assert same_items(download(conn, *VEHICLE, progress=lambda d, n: got.append((d, n))),
                      items)
    assert got == [(1, 4), (2, 4), (3, 4), (4, 4)]
    sent: list[str] = []

    def send(msg) -> None:  # a caller's own (e.g. locked) send is used when given
        sent.append(msg.get_type())
        conn.mav.send(msg)

    assert clear(conn, *VEHICLE, send=send) == M.MAV_MISSION_ACCEPTED
    assert sent == ["MISSION_CLEAR_ALL"]
    assert vehicle.server.mission == ()
    assert download(conn, *VEHICLE) == []


def test_refused_mission_returns_the_result(vehicle_factory):
    """Given an invalid item, then upload returns the vehicle's MAV_MISSION_RESULT (no
    exception) and the vehicle keeps its mission."""
    vehicle, conn = vehicle_factory()
    items = case1_and_more()
    assert upload(conn, *VEHICLE, items) == M.MAV_MISSION_ACCEPTED
    bad = list(items)
    bad[3] = bad[3]._replace(z=NAN)
    assert upload(conn, *VEHICLE, bad) == M.MAV_MISSION_INVALID_PARAM7
    assert same_items(vehicle.server.mission, items)


def test_lossy_link_still_completes(vehicle_factory):
    """Given a vehicle that drops 30 % of its replies (seeded), then upload and download of
    an 11-item mission still complete, equal, through the retries of both sides."""
    vehicle, conn = vehicle_factory(drop=0.3, seed=7)
    items = case1_and_more()
    assert upload(conn, *VEHICLE, items) == M.MAV_MISSION_ACCEPTED
    assert same_items(vehicle.server.mission, items)
    assert same_items(download(conn, *VEHICLE), items)
    assert vehicle.dropped > 0


def test_silent_vehicle_raises(vehicle_factory):
    """Given a vehicle whose replies are all lost, then upload, download and clear raise
    MissionError saying what went unanswered and that the vehicle was silent, once the
    silence limit has passed (re-sending meanwhile)."""
    _vehicle, conn = vehicle_factory(drop=1.0)
    fast = {"timeout_s": 0.05, "silence_s": 0.3}
    t0 = time.monotonic()
    with pytest.raises(MissionError, match=r"no answer to MISSION_COUNT\(11\): vehicle "
                       r"silent for 0\.3 s \([0-9]+ tries, 50 ms apart\)"):
        upload(conn, *VEHICLE, case1_and_more(), item_timeout_s=0.02, **fast)
    with pytest.raises(MissionError, match=r"no answer to MISSION_REQUEST_LIST: vehicle "
                       r"silent for 0\.3 s"):
        download(conn, *VEHICLE, item_timeout_s=0.02, **fast)
    with pytest.raises(MissionError, match=r"no MISSION_ACK: vehicle silent for 0\.3 s"):
        clear(conn, *VEHICLE, **fast)
    assert time.monotonic() - t0 < 2.0


def test_refusal_comes_with_the_vehicles_reason(vehicle_factory):
    """Given a vehicle that knows its airframe and a keyframe too fast for it, then
    upload_detailed returns DENIED with the vehicle's reason (its chunked STATUSTEXT put
    back together), upload keeps returning the result and fills `notes`, and an accepted
    upload has no notes."""
    vehicle_cfg = load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml")
    vehicle, conn = vehicle_factory(limits=MissionLimits(vehicle=vehicle_cfg))
    takeoff = MissionItem(0, M.MAV_FRAME_LOCAL_NED, M.MAV_CMD_NAV_TAKEOFF, 1, 1, 0.0, 0.0, 0.0,
                          NAN, 0, 0, -3.0)
    fast = MissionItem(1, M.MAV_FRAME_LOCAL_NED, MAV_CMD_POSE_KEYFRAME, 0, 1, 0.5, 0.0, 0.0,
                       0.0, local_xy(2.0), 0, -3.0)
    reason = check_mission([takeoff, fast], vehicle.server.limits).reason
    assert reason.startswith("item 1: tilt servo ") and " rad/s, limit " in reason
    answer = upload_detailed(conn, *VEHICLE, [takeoff, fast])
    assert answer == UploadResult(M.MAV_MISSION_DENIED, (reason,), 1) and not answer.accepted
    assert answer.describe() == f"MAV_MISSION_DENIED: {reason}"
    notes: list[str] = []
    assert upload(conn, *VEHICLE, [takeoff, fast], notes=notes) == M.MAV_MISSION_DENIED
    assert notes == [reason]
    ok = upload_detailed(conn, *VEHICLE, [takeoff, fast._replace(param1=3.0)])
    assert ok == UploadResult(M.MAV_MISSION_ACCEPTED, (), 1) and ok.accepted
    assert vehicle.server.mission[1].param1 == 3.0


def test_status_texts_reassemble_chunks():
    """Given chunked STATUSTEXT (one id, padded chunks, the last shorter) interleaved with a
    plain one and a repeat, then the texts come back whole, in order, the repeat once."""
    texts = StatusTexts()
    parts = statustext_chunks("item 3: needs 1903 rad/s > 1445 (85% of 1700): lengthen p1")
    msgs = [M.MAVLink_statustext_message(M.MAV_SEVERITY_WARNING, p.encode(), 9, i)
            for i, p in enumerate(parts)]
    texts.add(msgs[0])
    texts.add(M.MAVLink_statustext_message(M.MAV_SEVERITY_INFO, b"armed", 0, 0))
    for m in (*msgs[1:], *msgs):
        texts.add(m)
    assert texts.texts == ("armed",
                           "item 3: needs 1903 rad/s > 1445 (85% of 1700): lengthen p1")
