"""The FCU's parameter protocol towards ground stations: PARAM_REQUEST_LIST,
PARAM_REQUEST_READ and PARAM_SET answered from the parameter store (`fcu.params`); every
value is sent as MAV_PARAM_TYPE_REAL32 (`fcu.edge.gcs_server` dispatches the messages here).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from common.wire.mav_enums import MAV_PARAM_ERROR, MAV_PARAM_TYPE, MAV_SEVERITY
from common.wire.mavlink import MAV
from common.wire.mavlink_types.protocol import ParamRequestRead, ParamSet
from fcu.params import SPECS, ParamError, ParamStore

M = MAV
WARNING = MAV_SEVERITY.MAV_SEVERITY_WARNING
LIST_BURST = 10  # PARAM_VALUEs of a list per housekeeping tick (2 ms: 5,000 a second)


class ParamService:
    """The parameter protocol over one server's links: `send(msg, index)` to one link (None:
    all), `say(severity, text, index)` a STATUSTEXT, `armed()` the arming state, `on_params`
    told of every set in force."""

    def __init__(self, params: ParamStore, send: Callable[[Any, int | None], None],
                 say: Callable[[int, str, int | None], None], armed: Callable[[], bool],
                 on_params: Callable[[], None] | None = None) -> None:
        self.params = params
        self.send = send
        self.say = say
        self.armed = armed
        self.on_params = on_params
        self.lists: dict[int, int] = {}  # link -> the next parameter of its list

    def request_list(self, index: int) -> None:
        """PARAM_REQUEST_LIST: every parameter, in order, to the link that asked, LIST_BURST
        at a time (`tick`), so the list never holds the control loop up; a request again
        starts the list again."""
        self.lists[index] = 0

    def tick(self) -> None:
        """The next LIST_BURST parameters of each list under way."""
        for index, start in list(self.lists.items()):
            end = min(start + LIST_BURST, len(SPECS))
            for i in range(start, end):
                self.send_param(i, index)
            if end == len(SPECS):
                del self.lists[index]
            else:
                self.lists[index] = end

    def send_param(self, i: int, index: int | None = None) -> None:
        """PARAM_VALUE of parameter i to one link (None: all)."""
        name = SPECS[i].name
        self.send(M.MAVLink_param_value_message(name.encode(), self.params.values[name],
                                                MAV_PARAM_TYPE.MAV_PARAM_TYPE_REAL32,
                                                len(SPECS), i), index)

    @staticmethod
    def _param_id(msg: ParamRequestRead | ParamSet) -> bytes:
        """param_id as sent: str when decoded from the wire, bytes when built in-process."""
        raw: str | bytes = msg.param_id
        return raw.encode() if isinstance(raw, str) else raw

    @staticmethod
    def _param_name(msg: ParamRequestRead | ParamSet) -> str:
        raw: str | bytes = msg.param_id
        name = raw if isinstance(raw, str) else raw.decode("ascii", "replace")
        return name.rstrip("\x00")

    def param_read(self, index: int, msg: ParamRequestRead) -> None:
        """PARAM_REQUEST_READ: by index, or by name when the index is -1. A parameter that
        does not exist is answered, to the link that asked, with PARAM_ERROR
        (MAV_PARAM_ERROR_DOES_NOT_EXIST, the id and index as asked), as the parameter
        protocol says a get error is: the station need not wait for its timeout."""
        if msg.param_index >= 0:
            if msg.param_index < len(SPECS):
                self.send_param(msg.param_index, index)
                return
        elif self._param_name(msg) in self.params.values:
            self.send_param(self.params.index(self._param_name(msg)), index)
            return
        self.send(M.MAVLink_param_error_message(
            msg.get_srcSystem(), msg.get_srcComponent(), self._param_id(msg)[:16],
            msg.param_index, MAV_PARAM_ERROR.MAV_PARAM_ERROR_DOES_NOT_EXIST), index)

    def param_set(self, index: int, msg: ParamSet) -> None:
        """A set in force is echoed (PARAM_VALUE) to every link. A refusal answers the link
        that asked: PARAM_ERROR first (MAVSDK reports its error code: DOES_NOT_EXIST,
        VALUE_OUT_OF_RANGE, instead of a timeout), a STATUSTEXT with the reason, and for a
        known parameter the unchanged value (PARAM_VALUE, what older clients wait for)."""
        name = self._param_name(msg)
        raw_id = self._param_id(msg)
        if name not in self.params.values:
            self.send(M.MAVLink_param_error_message(
                msg.get_srcSystem(), msg.get_srcComponent(), raw_id[:16], -1,
                MAV_PARAM_ERROR.MAV_PARAM_ERROR_DOES_NOT_EXIST), index)
            self.say(WARNING, f"unknown parameter {name}", index)
            return
        i = self.params.index(name)
        try:
            self.params.set(name, float(msg.param_value), armed=self.armed())
        except ParamError as exc:
            self.send(M.MAVLink_param_error_message(
                msg.get_srcSystem(), msg.get_srcComponent(), name.encode(), i,
                MAV_PARAM_ERROR.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE), index)
            self.say(WARNING, str(exc), index)
            self.send_param(i, index)  # the unchanged value
            return
        if self.on_params is not None:
            self.on_params()
        self.send_param(i)  # the value now in force, to every link
