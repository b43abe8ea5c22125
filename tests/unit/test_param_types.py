"""Parameters in their real types (gcs/vehicle_link/param_wire.py, gcs/vehicle_link/params.py, the
`gcs param` commands): `param save` writes each parameter's MAV_PARAM_TYPE, integer values
ride as the vehicle carries them (ArduPilot casts, PX4 sends bytes) and survive a save/load
round trip, and a set the vehicle clamps is exit 1 "not taken: the vehicle keeps 127"."""

from __future__ import annotations

import struct

import pytest

from common.wire.mavlink import MAV
from common.wire.rounding import f32
from gcs.mission_files.param_files import parse_params
from gcs.vehicle_link import param_wire as pw
from tests.unit.scripted_autopilot import ScriptedAutopilot, gcs

M = MAV
pytestmark = pytest.mark.timeout(60)
INT8, INT16, INT32, REAL32 = (M.MAV_PARAM_TYPE_INT8, M.MAV_PARAM_TYPE_INT16,
                              M.MAV_PARAM_TYPE_INT32, M.MAV_PARAM_TYPE_REAL32)
ARDU_PARAMS = {"DISARM_DELAY": (10.0, INT8), "MAV_SYSID": (1.0, INT16),
               "LOG_BITMASK": (180222.0, INT32), "ATC_RAT_RLL_P": (f32(0.135), REAL32)}
# -1 is a NaN bit pattern, 2**24 + 1 is lost by a float cast, 0x7F800001 is a signalling
# NaN pattern that a float round trip turns into another integer
PX4_PARAMS = {"COM_FLTMODE1": (-1.0, INT32), "SYS_BIG": (16777217.0, INT32),
              "SYS_SNAN": (2139095041.0, INT32), "MPC_XY_VEL_MAX": (f32(12.5), REAL32)}


@pytest.fixture
def vehicles():
    made: list[ScriptedAutopilot] = []

    def make(kind: str, params) -> ScriptedAutopilot:
        v = ScriptedAutopilot(kind, params)
        made.append(v)
        return v

    yield make
    for v in made:
        v.close()




@pytest.mark.parametrize("encoding", [pw.C_CAST, pw.BYTEWISE])
@pytest.mark.parametrize("param_type,lo,hi", [(1, 0, 255), (2, -128, 127), (3, 0, 65535),
                                              (4, -32768, 32767), (5, 0, 2**32 - 1),
                                              (6, -2**31, 2**31 - 1)])
def test_integer_encodings_round_trip(encoding, param_type, lo, hi):
    """Given each integer type and both encodings, then its extremes and zero decode as
    they were encoded; bytewise they are the integer's own bytes, cast the float."""
    for v in (lo, 0, hi, 1):
        raw = pw.encode("P", v, param_type, encoding)
        if encoding == pw.BYTEWISE:
            fmt = {1: "<B", 2: "<b", 3: "<H", 4: "<h", 5: "<I", 6: "<i"}[param_type]
            assert raw[:struct.calcsize(fmt)] == struct.pack(fmt, v)
            assert pw.decode(raw, param_type, encoding) == v
        else:  # the float: exact up to 2**24, as ArduPilot keeps it beyond
            assert raw == struct.pack("<f", float(v))
            assert pw.decode(raw, param_type, encoding) == f32(v)


def test_value_checks_and_encoding_choice():
    """A fraction for an integer type and a bytewise value outside the type are refused
    with the name and the type; a cast one goes (the vehicle clamps); the encoding comes
    from the capabilities, else by autopilot."""
    with pytest.raises(pw.ParamValueError, match=r"DISARM_DELAY is an INT8: 5\.5"):
        pw.encode("DISARM_DELAY", 5.5, INT8, pw.C_CAST)
    with pytest.raises(pw.ParamValueError, match=r"outside -128\.\.127"):
        pw.encode("DISARM_DELAY", 300, INT8, pw.BYTEWISE)
    assert pw.encode("DISARM_DELAY", 300, INT8, pw.C_CAST) == struct.pack("<f", 300.0)
    assert pw.encoding_of(M.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE, True) == \
        pw.BYTEWISE
    assert pw.encoding_of(M.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST, False) == pw.C_CAST
    assert pw.encoding_of(0xFBEF, True) == pw.C_CAST
    assert pw.encoding_of(None, False) == pw.BYTEWISE


def test_ardupilot_save_writes_real_types(vehicles, capsys, tmp_path):
    """Given an ArduPilot-like vehicle, when `param save` runs, then every line has the
    parameter's own MAV_PARAM_TYPE (INT8 2, INT16 4, INT32 6, REAL32 9) and integer values
    as integers; `param list` and `param get` print them as integers too."""
    v = vehicles("ardupilot", ARDU_PARAMS)
    out_file = tmp_path / "ardu.params"
    code, out, err = gcs(capsys, v, "param", "save", str(out_file))
    assert code == 0, err
    text = out_file.read_text()
    entries = {e.name: (e.value, e.param_type) for e in parse_params(text)}
    assert entries == ARDU_PARAMS
    assert "\tDISARM_DELAY\t10\t2" in text and "\tLOG_BITMASK\t180222\t6" in text
    assert "# Stack: ArduPilot" in text
    code, out, _ = gcs(capsys, v, "param", "list")
    assert code == 0 and "LOG_BITMASK      180222" in out.splitlines()
    code, out, _ = gcs(capsys, v, "param", "get", "DISARM_DELAY")
    assert (code, out.strip()) == (0, "DISARM_DELAY = 10")


def test_ardupilot_clamped_set_is_not_taken(vehicles, capsys):
    """Given ArduPilot's DISARM_DELAY (INT8), when 300 is set, then the vehicle clamps it to
    127 and `param set` exits 1 with "not taken: the vehicle keeps 127"; 5 is taken (exit
    0) and went as a float (cast) with the parameter's type INT8; 5.5 is exit 2."""
    v = vehicles("ardupilot", ARDU_PARAMS)
    code, out, _ = gcs(capsys, v, "param", "set", "DISARM_DELAY", "300")
    assert code == 1 and "not taken: the vehicle keeps 127" in out, out
    assert v.params["DISARM_DELAY"] == (127.0, INT8)
    code, out, _ = gcs(capsys, v, "param", "set", "DISARM_DELAY", "5")
    assert code == 0 and out.strip() == "DISARM_DELAY = 5", out
    assert v.param_sets[-1] == ("DISARM_DELAY", INT8, struct.pack("<f", 5.0))
    code, _, err = gcs(capsys, v, "param", "set", "DISARM_DELAY", "5.5")
    assert code == 2 and "is an INT8: 5.5 is not an integer" in err, err
    assert v.params["DISARM_DELAY"] == (5.0, INT8)


def test_a_set_over_a_slow_link_is_not_judged_by_a_late_answer_to_its_read(capsys):
    """Given a vehicle whose answers take 1 s (the read before the set is asked again at
    0.7 s, so a second answer with the old value comes while the set waits), when
    ATC_RAT_RLL_P (REAL32: set as soon as read) is set to 0.25, then it is taken (exit 0):
    that answer is not the set's echo. (It used to be: "not taken: the vehicle keeps
    0.135", exit 1, the vehicle holding 0.25.)"""
    v = ScriptedAutopilot("ardupilot", ARDU_PARAMS, reply_delay_s=1.0)
    try:
        code, out, err = gcs(capsys, v, "param", "set", "ATC_RAT_RLL_P", "0.25")
    finally:
        v.close()
    assert code == 0 and out.strip() == "ATC_RAT_RLL_P = 0.25", out + err
    assert v.params["ATC_RAT_RLL_P"] == (0.25, REAL32)


@pytest.mark.parametrize("kind,params", [("ardupilot", ARDU_PARAMS), ("px4", PX4_PARAMS)])
def test_save_load_round_trip_keeps_types_and_values(vehicles, capsys, tmp_path, kind,
                                                     params):
    """Given an ArduPilot-like (cast) or PX4-like (bytewise, refuses a PARAM_SET of another
    type) vehicle, when its parameters are saved, changed, and the file loaded, then every
    value is back exactly (INT32 -1, 2**24 + 1 and a signalling-NaN pattern included), each
    set having gone with the parameter's type."""
    v = vehicles(kind, params)
    saved = tmp_path / f"{kind}.params"
    assert gcs(capsys, v, "param", "save", str(saved))[0] == 0
    assert {e.name: (e.value, e.param_type) for e in parse_params(saved.read_text())} == \
        params
    for name, (_value, ptype) in params.items():
        v.params[name] = (0.0, ptype)
    code, out, _ = gcs(capsys, v, "param", "load", str(saved))
    assert code == 0, out
    assert v.params == params
    assert sorted((n, t) for n, t, _ in v.param_sets) == sorted((n, t) for n, (_, t) in
                                                               params.items())


@pytest.mark.timeout(25)
def test_load_takes_each_echo_of_the_value_sent_at_once(vehicles, capsys, tmp_path,
                                                        monkeypatch):
    """Given a file loaded item by item, then a set whose echo is the value sent ends there:
    with the wait for a note after an echo (`ECHO_QUIET_S`, for `gcs param set`) made 30 s,
    the load of the vehicle's parameters still ends within the test's 25 s."""
    from gcs.vehicle_link import params as vl

    v = vehicles("ardupilot", ARDU_PARAMS)
    saved = tmp_path / "ardupilot.params"
    assert gcs(capsys, v, "param", "save", str(saved))[0] == 0
    monkeypatch.setattr(vl, "ECHO_QUIET_S", 30.0)
    code, out, _ = gcs(capsys, v, "param", "load", str(saved))
    assert code == 0 and f"loaded {len(ARDU_PARAMS)} of {len(ARDU_PARAMS)}" in out, out
