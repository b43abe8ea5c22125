"""`gcs param list` and `param save` print and write every parameter of a scripted vehicle
over loopback UDP whose list has ArduPilot's edge cases: a PARAM_VALUE with param_index
65535 (ArduPilot's echo of a parameter that changed) before the last index, an index sent
twice, the last index lost on the first pass (re-read by index), the count announced
first by a stray echo."""

from __future__ import annotations

import time
from typing import TypeVar

import pytest

from common.wire.mavlink import MAV
from gcs import cli
from gcs.mission_files.param_files import parse_params
from tests.unit.scripted_autopilot import ScriptedAutopilot, _RawParamValue

M = MAV
pytestmark = pytest.mark.timeout(60)
N = 37
ScriptedAutopilotT = TypeVar("ScriptedAutopilotT", bound=ScriptedAutopilot)
PARAMS = {f"P{i:03d}_X": (float(i), M.MAV_PARAM_TYPE_REAL32) for i in range(N)}


class ListQuirks(ScriptedAutopilot):
    """ArduPilot-like; its PARAM_REQUEST_LIST answer: an echo with index 65535 first, every
    index but the last, index 5 twice, an echo with index 65535 of parameter 3 where the
    last index would be. The last index comes when it is asked for by index."""

    def __init__(self) -> None:
        self.lists = 0
        self.reads: list[int] = []
        super().__init__("ardupilot", PARAMS)

    def _echo(self, i: int) -> None:
        name = self.names[i]
        value, param_type = self.params[name]
        self._send(_RawParamValue(name, self._raw(value, param_type), param_type,
                                  len(self.names), 65535))

    def _handle(self, msg) -> None:
        kind = msg.get_type()
        if kind == "PARAM_REQUEST_LIST":
            self.lists += 1
            self._echo(0)
            for i in range(N - 1):
                self._param_value(i)
                if i == 5:
                    self._param_value(i)
            self._echo(3)
            return
        if kind == "PARAM_REQUEST_READ" and msg.param_index >= 0:
            self.reads.append(msg.param_index)
        super()._handle(msg)


@pytest.fixture
def vehicle():
    v = ListQuirks()
    yield v
    v.close()


def gcs(capsys, vehicle: ScriptedAutopilot, *args: str) -> tuple[int, str, str]:
    code = cli.main([*args, "--connect", vehicle.url, "--wait", "5"])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_param_list_prints_all_n(capsys, vehicle):
    """Given a vehicle of N parameters whose list holds 65535 echoes, a duplicate and
    loses its last index, then `param list` prints all N, each once, in index order,
    having asked for the last index alone."""
    code, out, err = gcs(capsys, vehicle, "param", "list")
    assert code == 0, err
    lines = out.splitlines()
    assert [line.split()[0] for line in lines] == list(PARAMS)
    assert [line.split()[1] for line in lines] == [f"{i:g}" for i in range(N)]
    assert vehicle.reads == [N - 1]


def test_param_save_writes_all_n(capsys, vehicle, tmp_path):
    """Given the same vehicle, then `param save` writes N parameters and says N."""
    path = tmp_path / "v.params"
    code, out, err = gcs(capsys, vehicle, "param", "save", str(path))
    assert code == 0, err
    assert out.strip() == f"saved {N} parameters to {path}"
    assert sorted(e.name for e in parse_params(path.read_text())) == sorted(PARAMS)


def _listed(capsys, v: ScriptedAutopilotT) -> ScriptedAutopilotT:
    """`gcs param list` against `v` (closed after): it exits 0 printing v's parameters in
    index order."""
    try:
        code, out, err = gcs(capsys, v, "param", "list")
    finally:
        v.close()
    assert code == 0, err
    assert [line.split()[0] for line in out.splitlines()] == v.names
    return v


class ArduPilotReadQueue(ScriptedAutopilot):
    """ArduPilot's PARAM_REQUEST_READ handling: reads wait in one queue of 20 (GCS_Param's
    param_requests, shared by all links) served one each 5 ms; a read that finds it full is
    dropped. Its PARAM_REQUEST_LIST answer loses three indices in four."""

    QUEUE = 20

    def __init__(self, n: int) -> None:
        self.queue: list[int] = []
        self.dropped = 0
        self.peak = 0
        self._served_at = 0.0
        super().__init__("ardupilot", {f"Q{i:03d}_X": (float(i), M.MAV_PARAM_TYPE_REAL32)
                                       for i in range(n)})

    def _param_message(self, kind: str, msg) -> None:
        if kind == "PARAM_REQUEST_LIST":
            for i in range(0, len(self.names), 4):
                self._param_value(i)
        elif kind == "PARAM_REQUEST_READ" and msg.param_index >= 0:
            if len(self.queue) >= self.QUEUE:
                self.dropped += 1
                return
            self.queue.append(msg.param_index)
            self.peak = max(self.peak, len(self.queue))
        else:
            super()._param_message(kind, msg)

    def _send_due(self) -> None:
        super()._send_due()
        now = time.monotonic()
        if self.queue and now - self._served_at >= 0.005:
            self._served_at = now
            self._param_value(self.queue.pop(0))


def test_param_list_rereads_in_batches_that_ardupilots_queue_holds(capsys):
    """Given an ArduPilot-like vehicle of 80 parameters whose list loses 60 of them, and
    whose read queue holds 20 and drops the rest, then `param list` prints all 80 and no
    read was dropped: the missing are asked for ten at a time, the next ten once these
    are in. (All 60 at once, as before, overflowed its queue.)"""
    v = _listed(capsys, ArduPilotReadQueue(80))
    assert v.dropped == 0 and v.peak <= 10


class CountGrows(ScriptedAutopilot):
    """PX4-like: it numbers the parameters in use, and one comes into use while its first
    list is sent: after index 19 of 30, NEW_PARAM takes index 5, every index after it moves
    one up and param_count becomes 31 (the rest of that list is sent in the new order)."""

    def __init__(self) -> None:
        self.lists = 0
        super().__init__("px4", {f"P{i:03d}_X": (float(i), M.MAV_PARAM_TYPE_REAL32)
                                 for i in range(30)})

    def _param_message(self, kind: str, msg) -> None:
        if kind == "PARAM_REQUEST_LIST" and self.lists == 0:
            self.lists += 1
            for i in range(20):
                self._param_value(i)
            self.params["NEW_PARAM"] = (99.0, M.MAV_PARAM_TYPE_REAL32)
            self.names.insert(5, "NEW_PARAM")
            for i in range(20, 31):
                self._param_value(i)
            return
        self.lists += kind == "PARAM_REQUEST_LIST"
        super()._param_message(kind, msg)


def test_param_list_starts_again_when_the_vehicles_count_changes(capsys):
    """Given a vehicle whose parameter count grows from 30 to 31 during its list (a
    parameter in use from then on moves the indices after it), then `param list` prints
    the 31 of the new list, NEW_PARAM among them, having asked for the list again. (The
    values of both numberings were mixed: one name twice, NEW_PARAM missing.)"""
    v = _listed(capsys, CountGrows())
    assert "NEW_PARAM" in v.names and v.lists == 2


class CountChurns(ScriptedAutopilot):
    """A vehicle whose param_count is another one in each PARAM_VALUE it sends."""

    def __init__(self) -> None:
        self.sent_values = 0
        super().__init__("px4", {f"P{i:03d}_X": (float(i), M.MAV_PARAM_TYPE_REAL32)
                                 for i in range(10)})

    def _param_value(self, i: int) -> None:
        self.sent_values += 1
        name = self.names[i]
        value, param_type = self.params[name]
        self._send(_RawParamValue(name, self._raw(value, param_type), param_type,
                                  len(self.names) + self.sent_values, i))


def test_param_list_gives_up_on_a_count_that_keeps_changing(capsys):
    """Given a vehicle whose param_count changes with every value, then `param list` exits 1
    saying so, with the counts it saw, after three new starts."""
    v = CountChurns()
    try:
        code, out, err = gcs(capsys, v, "param", "list")
    finally:
        v.close()
    assert code == 1 and out == ""
    assert "the vehicle's parameter count kept changing during the list: 11, 12, 13, 14, 15" \
        in err
