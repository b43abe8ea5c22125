"""How a parameter's value rides in the float32 `param_value` of PARAM_VALUE / PARAM_SET.

`param_type` (MAV_PARAM_TYPE) names the real type; integer types go one of two ways
(MAVLink's parameter protocol, AUTOPILOT_VERSION capabilities):

- C cast (MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST; ArduPilot, which announces neither
  bit): the value converted to a float (exact up to 2**24; the vehicle casts it back);
- bytewise (MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE; PX4): the integer's own
  little-endian bytes in the four bytes of the float, the rest zero (an INT32 of -1 is a
  NaN bit pattern). The bytes are kept as they are: a float round trip would turn a
  signalling NaN pattern into another integer.

Float types are the float either way. This FCU's parameters are all REAL32.
"""

from __future__ import annotations

import math
import struct

from common.wire.mavlink import MAV
from common.wire.rounding import f32

M = MAV
C_CAST, BYTEWISE = "c_cast", "bytewise"
REAL32 = M.MAV_PARAM_TYPE_REAL32
FLOAT_TYPES = frozenset({M.MAV_PARAM_TYPE_REAL32, M.MAV_PARAM_TYPE_REAL64})
INT_RANGES = {M.MAV_PARAM_TYPE_UINT8: (0, 2**8 - 1), M.MAV_PARAM_TYPE_INT8: (-2**7, 2**7 - 1),
              M.MAV_PARAM_TYPE_UINT16: (0, 2**16 - 1),
              M.MAV_PARAM_TYPE_INT16: (-2**15, 2**15 - 1),
              M.MAV_PARAM_TYPE_UINT32: (0, 2**32 - 1),
              M.MAV_PARAM_TYPE_INT32: (-2**31, 2**31 - 1),
              M.MAV_PARAM_TYPE_UINT64: (0, 2**64 - 1),
              M.MAV_PARAM_TYPE_INT64: (-2**63, 2**63 - 1)}
# the integer types that fit the four bytes, by their struct format
_BYTEWISE_FORMATS = {M.MAV_PARAM_TYPE_UINT8: "<B", M.MAV_PARAM_TYPE_INT8: "<b",
                     M.MAV_PARAM_TYPE_UINT16: "<H", M.MAV_PARAM_TYPE_INT16: "<h",
                     M.MAV_PARAM_TYPE_UINT32: "<I", M.MAV_PARAM_TYPE_INT32: "<i"}
_FLOAT = struct.Struct("<f")
_SET_TAIL = struct.Struct("<BB16sB")  # PARAM_SET after param_value


class ParamValueError(ValueError):
    """A value that the parameter's type cannot carry (one line: name, value, type)."""


def type_name(param_type: int) -> str:
    """'INT8', 'REAL32', ... (or the number)."""
    entry = M.enums["MAV_PARAM_TYPE"].get(param_type)
    return entry.name.removeprefix("MAV_PARAM_TYPE_") if entry is not None else \
        str(param_type)


def encoding_of(capabilities: int | None, ardupilot: bool) -> str:
    """BYTEWISE or C_CAST from AUTOPILOT_VERSION's capabilities; when they say neither (or
    are unknown): C_CAST for ArduPilot, BYTEWISE otherwise (PX4's)."""
    if capabilities is not None:
        if capabilities & M.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE:
            return BYTEWISE
        if capabilities & M.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST:
            return C_CAST
    return C_CAST if ardupilot else BYTEWISE


def intended(name: str, value: float, param_type: int) -> float:
    """What the vehicle holds once it takes `value`: the float32 for float types, the
    integer for integer types; ParamValueError for a fraction given to an integer type, or
    a value no float32 carries."""
    if param_type in FLOAT_TYPES or param_type not in INT_RANGES:
        try:
            return f32(value)
        except OverflowError:
            raise ParamValueError(f"{name}: {value:g} does not fit a float32") from None
    if not (math.isfinite(value) and float(value).is_integer()):
        raise ParamValueError(f"{name} is an {type_name(param_type)}: {value:g} is not an "
                              "integer")
    return float(int(value))


def encode(name: str, value: float, param_type: int, encoding: str) -> bytes:
    """The four bytes of `param_value` for `value` (`intended` first). Bytewise, a value
    outside the type's range is a ParamValueError (its bytes cannot carry it); cast, it
    goes as it is and the vehicle clamps or refuses it."""
    v = intended(name, value, param_type)
    fmt = _BYTEWISE_FORMATS.get(param_type) if encoding == BYTEWISE else None
    if fmt is None:
        try:
            return _FLOAT.pack(v)
        except OverflowError:
            raise ParamValueError(f"{name}: {value:g} does not fit a float32") from None
    lo, hi = INT_RANGES[param_type]
    if not lo <= v <= hi:
        raise ParamValueError(f"{name} is an {type_name(param_type)}: {value:g} is outside "
                              f"{lo}..{hi}")
    return struct.pack(fmt, int(v)).ljust(4, b"\0")


def decode(raw: bytes, param_type: int, encoding: str) -> float:
    """The value of `param_value`'s four bytes."""
    fmt = _BYTEWISE_FORMATS.get(param_type) if encoding == BYTEWISE else None
    if fmt is None:
        return float(_FLOAT.unpack(raw[:4])[0])
    return float(struct.unpack(fmt, raw[:struct.calcsize(fmt)])[0])


def raw_value(msg: MAV.MAVLink_message) -> bytes:
    """`param_value`'s four bytes as they came: the first field of the payload, after the
    header of 10 bytes (MAVLink 2, magic 0xFD) or 6 (MAVLink 1); MAVLink 2 drops trailing
    zero bytes, given back here. A message built here (never packed): its float."""
    buf = msg.get_msgbuf()
    if buf:
        start = 10 if buf[0] == 0xFD else 6
        return bytes(buf[start:start + 4]).ljust(4, b"\0")
    return _FLOAT.pack(msg.param_value)


def param_set_message(target_system: int, target_component: int, name: str, raw: bytes,
                      param_type: int) -> MAV.MAVLink_message:
    """PARAM_SET of `name` with `param_value`'s four bytes `raw` (`encode`): pymavlink's
    message, its `pack` bound to one that sends those bytes as they are."""
    msg = MAV.MAVLink_param_set_message(target_system, target_component, name.encode(),
                                        _FLOAT.unpack(raw)[0], param_type)

    def pack(mav: MAV.MAVLink, force_mavlink1: bool = False) -> bytes:
        body = raw + _SET_TAIL.pack(msg.target_system, msg.target_component,
                                    msg._param_id_raw, msg.param_type)
        return bytes(msg._pack(mav, msg.crc_extra, body, force_mavlink1=force_mavlink1))

    msg.pack = pack
    return msg
