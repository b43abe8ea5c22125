"""`gcs param list` and `param save` print and write every parameter of a scripted vehicle
over loopback UDP whose list has ArduPilot's edge cases: a PARAM_VALUE with param_index
65535 (ArduPilot's echo of a parameter that changed) before the last index, an index sent
twice, the last index lost on the first pass (re-read by index), the count announced
first by a stray echo."""

from __future__ import annotations

import pytest

from common.wire.mavlink import MAV
from gcs import cli
from gcs.mission_files.param_files import parse_params
from tests.unit.scripted_autopilot import ScriptedAutopilot, _RawParamValue

M = MAV
pytestmark = pytest.mark.timeout(60)
N = 37
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
