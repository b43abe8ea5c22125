"""`gcs log record` (gcs/cli/telemetry.py, the session's tlog): the count it prints is the
number of records in its file, heard and sent alike, and the file's timestamps never go
back, even when the wall clock steps back during the recording. The file is read back with
pymavlink's mavutil, as mavlogdump.py reads it."""

from __future__ import annotations

import itertools
import re
import time
import types

import pytest
from pymavlink import mavutil

import gcs.vehicle_link.session
from common.wire.mavlink import MAV
from gcs import cli
from tests.unit.scripted_autopilot import ScriptedAutopilot

M = MAV
pytestmark = pytest.mark.timeout(60)


class Streaming(ScriptedAutopilot):
    """A PX4-like vehicle that streams ATTITUDE at about 200 Hz to whoever it heard."""

    def _run(self) -> None:
        self._sent_at = 0.0
        super()._run()

    def _send(self, msg) -> None:
        super()._send(msg)
        now = time.monotonic()
        if self._peer is not None and now - self._sent_at > 0.005:
            self._sent_at = now
            super()._send(M.MAVLink_attitude_message(int(now * 1e3) & 0xFFFFFFFF,
                                                     0.1, 0.2, 0.3, 0.0, 0.0, 0.0))

    def _handle(self, msg) -> None:
        super()._handle(msg)
        self._send(M.MAVLink_attitude_message(0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))


def read_tlog(path) -> list[tuple[str, float]]:
    log = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
    out = []
    while (msg := log.recv_match()) is not None:
        if msg.get_type() != "BAD_DATA":
            out.append((msg.get_type(), msg._timestamp))
    return out


@pytest.fixture
def vehicle():
    v = Streaming("px4")
    yield v
    v.close()


def record(capsys, vehicle, path, seconds: float) -> int:
    code = cli.main(["log", "record", str(path), "--duration", str(seconds), "--connect",
                     vehicle.url, "--wait", "5"])
    out = capsys.readouterr().out
    assert code == 0
    found = re.search(r"recorded (\d+) messages to ", out)
    assert found, out
    return int(found.group(1))


def test_count_is_the_records_in_the_file(capsys, vehicle, tmp_path):
    """Given a vehicle streaming at about 100-200 Hz, when 1.5 s are recorded, then the
    count printed equals the records mavutil reads from the .tlog, which hold what was
    heard (ATTITUDE, HEARTBEAT) and what was sent (the station's HEARTBEAT)."""
    path = tmp_path / "flight.tlog"
    count = record(capsys, vehicle, path, 1.5)
    records = read_tlog(path)
    assert count == len(records) > 100
    kinds = {k for k, _ in records}
    assert {"ATTITUDE", "HEARTBEAT"} <= kinds
    stamps = [t for _, t in records]
    assert all(b >= a for a, b in itertools.pairwise(stamps))


def test_stamps_never_go_back_when_the_wall_clock_does(capsys, vehicle, tmp_path,
                                                       monkeypatch):
    """Given a wall clock that steps back 10 s half a second into the recording, then the
    tlog's timestamps are still monotonic (one clock: the wall time at opening plus the
    monotonic time since)."""
    start = time.monotonic()

    def stepping() -> float:
        back = 10.0 if time.monotonic() - start > 0.5 else 0.0
        return time.time() - back

    clock = types.SimpleNamespace(**{k: getattr(time, k) for k in dir(time)
                                     if not k.startswith("_")})
    clock.time = stepping
    monkeypatch.setattr(gcs.vehicle_link.session, "time", clock)
    path = tmp_path / "step.tlog"
    count = record(capsys, vehicle, path, 1.2)
    stamps = [t for _, t in read_tlog(path)]
    assert count == len(stamps) > 50
    assert all(b >= a for a, b in itertools.pairwise(stamps))
