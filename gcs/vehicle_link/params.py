"""Parameters in their real types: read all or one, set one, encoded as the vehicle
carries integers (`gcs.param_wire`, chosen by its AUTOPILOT_VERSION or autopilot)."""

from __future__ import annotations

import time
import weakref
from dataclasses import dataclass
from typing import Any

from common.mavlink import MAV
from gcs import param_wire
from gcs.autopilot import ARDUPILOT, autopilot_of
from gcs.session import GcsError, Session

M = MAV


@dataclass(frozen=True)
class ParamValue:
    """A parameter's value (an integer for the integer types) and its MAV_PARAM_TYPE."""

    value: float
    param_type: int = M.MAV_PARAM_TYPE_REAL32

    @property
    def is_integer(self) -> bool:
        return self.param_type not in param_wire.FLOAT_TYPES

    def text(self) -> str:
        """As `gcs param` prints it: an integer type as an integer, a float with :g."""
        return str(int(self.value)) if self.is_integer else f"{self.value:g}"


_ENCODINGS: weakref.WeakKeyDictionary[Session, str] = weakref.WeakKeyDictionary()
ECHO_QUIET_S = 0.2  # after a set's echo, how long to listen for a later echo or a reason


def autopilot_version(session: Session, timeout: float = 0.5) -> Any:
    """The vehicle's AUTOPILOT_VERSION: the last one heard, else asked for once
    (REQUEST_MESSAGE); None when it sends none."""
    s = session
    ver = s.conn.messages.get("AUTOPILOT_VERSION")
    if ver is None:
        try:
            s.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION,
                      timeout=timeout, retries=1)
            ver = s.conn.messages.get("AUTOPILOT_VERSION") or \
                s.recv(["AUTOPILOT_VERSION"], timeout=timeout)
        except GcsError:
            ver = None
    return ver if ver is not None and ver.get_srcSystem() == s.target_system else None


def param_encoding(session: Session) -> str:
    """How the vehicle carries integer parameters (`gcs.param_wire`): its AUTOPILOT_VERSION
    capabilities, else by autopilot (ArduPilot casts, PX4 sends bytes); asked once per
    session."""
    known = _ENCODINGS.get(session)
    if known is None:
        ver = autopilot_version(session)
        hb = session.heartbeat_msg
        ardupilot = hb is not None and autopilot_of(hb).kind == ARDUPILOT
        known = param_wire.encoding_of(None if ver is None else ver.capabilities, ardupilot)
        _ENCODINGS[session] = known
    return known


def _decoded(session: Session, raw: bytes, param_type: int) -> ParamValue:
    """A PARAM_VALUE's four bytes as the value of its type (asks for the encoding only
    for an integer type: float parameters read the same either way)."""
    encoding = param_wire.C_CAST if param_type in param_wire.FLOAT_TYPES else \
        param_encoding(session)
    return ParamValue(param_wire.decode(raw, param_type, encoding), param_type)


def param_values(session: Session, timeout: float = 5.0) -> dict[str, ParamValue]:
    """All parameters with their types (PARAM_REQUEST_LIST), re-reading missing indices
    once; `timeout` without a new parameter ends it.

    Only a PARAM_VALUE whose param_index is within param_count fills the list: ArduPilot
    also sends PARAM_VALUE with param_index 65535 (-1) for a parameter that changes or is
    read by name (its GCS_Param), and counting such an echo as an index ended the list
    one parameter short. The vehicle's latest param_count holds."""
    s = session
    s.send(M.MAVLink_param_request_list_message(s.target_system, s.target_component))
    values: dict[int, tuple[str, bytes, int]] = {}
    count = None
    deadline = time.monotonic() + timeout
    quiet_until = time.monotonic() + 1.0
    while time.monotonic() < deadline:
        msg = s.recv(["PARAM_VALUE"], timeout=0.2)
        if msg is None:
            if count is not None and time.monotonic() > quiet_until:
                missing = [i for i in range(count) if i not in values]
                if not missing:
                    break
                for i in missing:  # the spec's recovery: request what did not arrive
                    s.send(M.MAVLink_param_request_read_message(
                        s.target_system, s.target_component, b"", i))
                quiet_until = time.monotonic() + 1.0
            continue
        if msg.get_srcSystem() != s.target_system:
            continue
        if count != msg.param_count:  # the first, or the vehicle's count changed
            count = msg.param_count
            values = {i: v for i, v in values.items() if i < count}
        index = msg.param_index
        if not 0 <= index < count:  # 65535: an echo of a set or of a read by name
            continue
        if index not in values:
            deadline = max(deadline, time.monotonic() + timeout)
        values[index] = (msg.param_id, param_wire.raw_value(msg), msg.param_type)
        quiet_until = time.monotonic() + 0.3
        if len(values) == count:
            break
    if count is None:
        raise GcsError("no PARAM_VALUE answered PARAM_REQUEST_LIST")
    if len(values) != count:
        raise GcsError(f"received {len(values)} of {count} parameters")
    return {name: _decoded(s, raw, ptype) for _, (name, raw, ptype) in sorted(values.items())}


def param_list(session: Session, timeout: float = 5.0) -> dict[str, float]:
    """All parameters' values (`param_values` without the types)."""
    return {name: p.value for name, p in param_values(session, timeout).items()}


def param_read(session: Session, name: str, timeout: float = 2.0) -> ParamValue:
    """One parameter with its type (PARAM_REQUEST_READ by name, three tries)."""
    s = session
    for _ in range(3):
        s.send(M.MAVLink_param_request_read_message(s.target_system, s.target_component,
                                                    name.encode(), -1))
        deadline = time.monotonic() + timeout / 3
        while time.monotonic() < deadline:
            msg = s.recv(["PARAM_VALUE"], timeout=0.1)
            if msg is not None and msg.param_id == name and \
                    msg.get_srcSystem() == s.target_system:
                return _decoded(s, param_wire.raw_value(msg), msg.param_type)
    raise GcsError(f"parameter {name} not answered (unknown to the vehicle?)")


def param_get(session: Session, name: str, timeout: float = 2.0) -> float:
    return param_read(session, name, timeout).value


def param_set(session: Session, name: str, value: float, timeout: float = 2.0, *,
              param_type: int | None = None) -> tuple[float, list[str]]:
    """Set a parameter in its real type (read first unless `param_type` is given), encoded
    as the vehicle carries it; returns (value now in force, STATUSTEXTs heard meanwhile).
    The value in force is the echo that equals what was sent if one came within
    ECHO_QUIET_S of the first (a stale answer to the read may come first), else the last
    echo: a vehicle that clamps the value echoes the clamped one. ParamValueError for a
    value the type cannot carry."""
    s = session
    if param_type is None:
        param_type = param_read(s, name, timeout).param_type
    encoding = param_wire.C_CAST if param_type in param_wire.FLOAT_TYPES else \
        param_encoding(s)
    raw = param_wire.encode(name, value, param_type, encoding)
    want = param_wire.intended(name, value, param_type)
    texts: list[str] = []
    echoes: list[float] = []
    for _ in range(3):
        s.send(param_wire.param_set_message(s.target_system, s.target_component, name, raw,
                                            param_type))
        deadline = time.monotonic() + timeout / 3
        while (left := deadline - time.monotonic()) > 0.0:
            msg = s.recv(["PARAM_VALUE", "STATUSTEXT"], timeout=min(0.1, left))
            if msg is None or msg.get_srcSystem() != s.target_system:
                continue
            if msg.get_type() == "STATUSTEXT":
                texts.append(msg.text)
            elif msg.param_id == name:
                echoes.append(param_wire.decode(param_wire.raw_value(msg), param_type,
                                                encoding))
                deadline = time.monotonic() + ECHO_QUIET_S  # a refusal may come just after
        if echoes:
            return (want if want in echoes else echoes[-1]), texts
    raise GcsError(f"parameter {name} not answered")
