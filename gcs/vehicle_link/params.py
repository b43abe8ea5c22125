"""Parameters in their real types: read all or one, set one, encoded as the vehicle
carries integers (`gcs.vehicle_link.param_wire`, chosen by its AUTOPILOT_VERSION or autopilot).

Waits follow `gcs.vehicle_link.patience`: a read or set is re-sent each PARAM.resend_s without its
PARAM_VALUE and given up when the vehicle falls silent or at the ceiling (`timeout`); the
list goes on while parameters come, re-requests what is missing when they pause, and is
given up on silence or when no new parameter has come for its ceiling."""

from __future__ import annotations

import time
import weakref
from dataclasses import dataclass
from typing import Any

from common.wire.mav_enums import MAV_PARAM_ERROR
from common.wire.mavlink import MAV
from gcs.autopilot import ARDUPILOT, autopilot_of
from gcs.vehicle_link import param_wire
from gcs.vehicle_link.patience import PARAM, PARAM_LIST, Wait
from gcs.vehicle_link.session import GcsError, Session

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
# Missing list indices are re-read by index this many at a time, the next batch once these
# are in (QGroundControl too asks in batches of about ten): ArduPilot queues at most 20
# PARAM_REQUEST_READs for all its links together and drops the rest (GCS_Param's
# param_requests), so asking for every missing index at once lost most of them and crowded
# out other stations' reads.
REREAD_BATCH = 10
MAX_RESTARTS = 3  # a list whose param_count changes more often than this is given up
PAUSE_S = 0.3  # the list's stream paused this long after a parameter: re-read what is missing


def autopilot_version(session: Session, timeout: float = 0.5) -> Any:
    """The vehicle's AUTOPILOT_VERSION: the last one heard, else asked for once
    (REQUEST_MESSAGE); None when it sends none."""
    s = session
    ver = s.conn.messages.get("AUTOPILOT_VERSION")
    if not s.from_autopilot(ver):  # none yet, or a companion computer's
        try:
            s.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION,
                      timeout=timeout, retries=1)
            ver = s.conn.messages.get("AUTOPILOT_VERSION")
            if not s.from_autopilot(ver):
                ver = s.recv(["AUTOPILOT_VERSION"], timeout=timeout)
        except GcsError:
            ver = None
    return ver if s.from_autopilot(ver) else None


def param_encoding(session: Session) -> str:
    """How the vehicle carries integer parameters (`gcs.vehicle_link.param_wire`): its
    AUTOPILOT_VERSION capabilities, else by autopilot (ArduPilot casts, PX4 sends bytes); asked once
    per session."""
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


def param_values(session: Session, timeout: float = PARAM_LIST.ceiling_s
                 ) -> dict[str, ParamValue]:
    """All parameters with their types (PARAM_REQUEST_LIST), re-reading missing indices
    when the stream pauses; given up when the vehicle falls silent or `timeout` passes
    without a new parameter (`gcs.vehicle_link.patience`).

    Only a PARAM_VALUE whose param_index is within param_count fills the list: ArduPilot
    also sends PARAM_VALUE with param_index 65535 (-1) for a parameter that changes or is
    read by name (its GCS_Param), and counting such an echo as an index ended the list
    one parameter short. When the vehicle's param_count changes, its indices have moved:
    the list starts again (`_ListRead._restart`)."""
    s = session
    read = _ListRead(s, Wait(PARAM_LIST.but(ceiling_s=timeout)))
    why = ""
    while not (why := read.wait.expired()):
        msg = s.recv(["PARAM_VALUE"], timeout=min(0.2, read.wait.left()))
        read.wait.note_session(s)
        if s.from_autopilot(msg) and read.take(msg):  # not a camera's or gimbal's
            break
        if read.paused():  # checked whatever came: others' values must not put it off
            break
    if read.count is None:
        raise GcsError(f"no PARAM_VALUE answered PARAM_REQUEST_LIST{why}")
    if len(read.values) != read.count:
        raise GcsError(f"received {len(read.values)} of {read.count} parameters{why}")
    return {name: _decoded(s, raw, ptype)
            for _, (name, raw, ptype) in sorted(read.values.items())}


class _ListRead:
    """A parameter list being read: the values by index, the vehicle's count, and the
    indices re-read by index and not yet answered. Sends PARAM_REQUEST_LIST on creation."""

    def __init__(self, session: Session, wait: Wait) -> None:
        s = self.s = session
        self.wait = wait  # its ceiling restarts at each new index
        self.request = M.MAVLink_param_request_list_message(s.target_system,
                                                            s.target_component)
        self.values: dict[int, tuple[str, bytes, int]] = {}
        self.count: int | None = None
        self.counts: list[int] = []  # each param_count the vehicle announced, in turn
        self.asked: set[int] = set()
        self.streaming = False  # an index not asked for came since the last re-read
        self.quiet_until = time.monotonic() + PARAM_LIST.resend_s
        s.send(self.request)

    def take(self, msg: Any) -> bool:
        """A PARAM_VALUE of the autopilot; True when the list is whole. An index of the
        list restarts the ceiling when new; the last of a re-read batch asks the next."""
        self.wait.heard()
        index = msg.param_index
        if self.count is None:
            self.count = msg.param_count
            self.counts.append(msg.param_count)
        elif self.count != msg.param_count:
            if msg.param_count in self.counts:
                return False  # sent before the change, come late
            self._restart(msg.param_count)
        if not 0 <= index < msg.param_count:  # 65535: an echo of a set or a read by name
            return False
        if index not in self.values:
            self.wait.progressed()
        self.values[index] = (msg.param_id, param_wire.raw_value(msg), msg.param_type)
        self.quiet_until = time.monotonic() + PAUSE_S
        if len(self.values) == self.count:
            return True
        if index not in self.asked:
            self.streaming = True  # the list's own stream goes on
            return False
        self.asked.discard(index)
        if not self.asked and not self.streaming:
            self._ask_again()  # the batch is in and the stream has stopped: the next, now
        return False

    def _restart(self, count: int) -> None:
        """The vehicle's param_count changed: its list changed under the read, and the
        indices with it (PX4 numbers the parameters in use, ArduPilot those of the enabled
        subsystems: one more moves every index after it). Every value is read again, from
        a new PARAM_REQUEST_LIST; GcsError after MAX_RESTARTS."""
        self.counts.append(count)
        if len(self.counts) > MAX_RESTARTS + 1:
            raise GcsError("the vehicle's parameter count kept changing during the list: "
                           + ", ".join(map(str, self.counts)))
        self.count, self.values, self.asked = count, {}, set()
        self.s.send(self.request)
        self.quiet_until = time.monotonic() + PARAM_LIST.resend_s
        self.streaming = False

    def paused(self) -> bool:
        """Nothing came for a while: once the pause is long enough, ask again (`_ask_again`);
        True when nothing is missing."""
        if time.monotonic() <= self.quiet_until:
            return False
        return self._ask_again()

    def _ask_again(self) -> bool:
        """The list asked for again (nothing heard yet), or the first REREAD_BATCH indices
        that did not arrive, each by index (the spec's recovery), kept in `asked`; True
        when none is missing."""
        s = self.s
        self.quiet_until = time.monotonic() + PARAM_LIST.resend_s
        self.streaming = False
        if self.count is None:  # nothing yet: ask again
            s.send(self.request)
            self.wait.sent()
            return False
        missing = [i for i in range(self.count) if i not in self.values]
        self.asked = set(missing[:REREAD_BATCH])
        for i in missing[:REREAD_BATCH]:
            s.send(M.MAVLink_param_request_read_message(s.target_system, s.target_component,
                                                        b"", i))
        return not missing


def param_list(session: Session, timeout: float = PARAM_LIST.ceiling_s) -> dict[str, float]:
    """All parameters' values (`param_values` without the types)."""
    return {name: p.value for name, p in param_values(session, timeout).items()}


class ParamRefused(GcsError):
    """The vehicle answered a parameter with PARAM_ERROR; `reason` says its error."""

    def __init__(self, name: str, reason: str) -> None:
        super().__init__(f"parameter {name}: {reason}")
        self.reason = reason


def param_error_text(error: int) -> str:
    """A PARAM_ERROR's error for a person: "does not exist (MAV_PARAM_ERROR_DOES_NOT_EXIST)"."""
    try:
        member = MAV_PARAM_ERROR(error)
    except ValueError:
        return f"PARAM_ERROR {error}"
    return f"{member.name.removeprefix('MAV_PARAM_ERROR_').lower().replace('_', ' ')} " \
        f"({member.name})"


def param_read(session: Session, name: str, timeout: float = PARAM.ceiling_s) -> ParamValue:
    """One parameter with its type (PARAM_REQUEST_READ by name, re-sent each
    PARAM.resend_s); GcsError at once on a PARAM_ERROR for it (this FCU, newer autopilots),
    else when the vehicle falls silent or at the ceiling `timeout` (PX4 and ArduPilot do
    not answer a name they do not know)."""
    s = session
    request = M.MAVLink_param_request_read_message(s.target_system, s.target_component,
                                                   name.encode(), -1)
    s.send(request)
    wait = Wait(PARAM.but(ceiling_s=timeout))
    while not (why := wait.expired()):
        msg = s.recv(["PARAM_VALUE", "PARAM_ERROR"], timeout=min(0.1, wait.left()))
        wait.note_session(s)
        if s.from_autopilot(msg) and msg.param_id == name:
            if msg.get_type() == "PARAM_ERROR":
                raise ParamRefused(name, param_error_text(msg.error))
            return _decoded(s, param_wire.raw_value(msg), msg.param_type)
        if wait.due() and not wait.expired():
            s.send(request)
            wait.sent()
    hint = "" if why.startswith(":") else " (unknown to the vehicle?)"
    raise GcsError(f"parameter {name} not answered{why}{wait.tries_text()}{hint}")


def param_get(session: Session, name: str, timeout: float = PARAM.ceiling_s) -> float:
    return param_read(session, name, timeout).value


def param_set(session: Session, name: str, value: float, timeout: float = PARAM.ceiling_s, *,
              param_type: int | None = None, linger: bool = True) -> tuple[float, list[str]]:
    """Set a parameter in its real type (read first unless `param_type` is given), encoded
    as the vehicle carries it; returns (value now in force, STATUSTEXTs heard meanwhile).
    PARAM_SET is re-sent each PARAM.resend_s without an echo (the same value again: the
    parameter protocol's recovery); GcsError when the vehicle falls silent or at the
    ceiling `timeout`. The value in force is the echo that equals what was sent if one
    came within ECHO_QUIET_S of the first (a stale answer to the read may come first),
    else the last echo: a vehicle that clamps the value echoes the clamped one. An echo of
    another value is believed when it comes again: the first is answered with PARAM_SET
    sent again (the parameter protocol's recovery), as it may be a late answer to the read
    (a link slower than the read's re-send brings two). Without
    `linger` (a file loaded item by item) an echo of the value sent ends the wait at once,
    with no time left for a note sent after it. ParamValueError for a value the type cannot
    carry."""
    s = session
    if param_type is None:
        param_type = param_read(s, name, timeout).param_type
    encoding = param_wire.C_CAST if param_type in param_wire.FLOAT_TYPES else \
        param_encoding(s)
    raw = param_wire.encode(name, value, param_type, encoding)
    want = param_wire.intended(name, value, param_type)
    texts: list[str] = []
    echoes: list[float] = []
    request = param_wire.param_set_message(s.target_system, s.target_component, name, raw,
                                           param_type)
    s.send(request)
    wait = Wait(PARAM.but(ceiling_s=timeout))
    quiet_until = None  # after the first echo: how long a later one may still come
    while not (why := wait.expired()):
        now = time.monotonic()
        if quiet_until is not None and now >= quiet_until:
            break
        left = wait.left() if quiet_until is None else min(wait.left(), quiet_until - now)
        msg = s.recv(["PARAM_VALUE", "STATUSTEXT"], timeout=min(0.1, max(left, 0.001)))
        wait.note_session(s)
        if s.from_autopilot(msg):
            if msg.get_type() == "STATUSTEXT":
                texts.append(msg.text)
            elif msg.param_id == name:
                echoes.append(param_wire.decode(param_wire.raw_value(msg), param_type,
                                                encoding))
                if echoes[-1] != want and echoes.count(echoes[-1]) == 1 and \
                        want not in echoes:
                    s.send(request)  # maybe a late answer to the read: the set asked again,
                    wait.sent()      # a value other than sent is taken when it comes again
                    continue
                if not linger and echoes[-1] == want:
                    break  # taken as sent
                quiet_until = time.monotonic() + ECHO_QUIET_S  # a refusal may come after
        if quiet_until is None and wait.due() and not wait.expired():
            s.send(request)
            wait.sent()
    if echoes:
        return (want if want in echoes else echoes[-1]), texts
    raise GcsError(f"parameter {name} not answered{why}{wait.tries_text()}")
