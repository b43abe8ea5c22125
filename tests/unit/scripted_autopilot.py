"""A scripted ArduPilot-like or PX4-like vehicle on loopback UDP, for the ground station's
mission and parameter commands (tests/unit/test_mission_home.py, test_param_types.py).

What it does is what the real ones do, written here from their behaviour, not from
gcs/: ArduPilot keeps home at mission seq 0 (its own home, whatever was uploaded there),
refuses local-frame items (MAV_MISSION_UNSUPPORTED_FRAME, no text), casts parameter values
(the float is converted to the parameter's type and clamped to its range) and answers a
download in the plain global frames (0, 3, 10); PX4 answers one in the _INT frames (5, 6:
it keeps only whether an altitude is relative), numbers a
mission from 0, carries integer parameters bytewise and refuses a PARAM_SET whose type is
not the parameter's. An item it did not ask for: ArduPilot answers MAV_MISSION_INVALID_SEQUENCE
during its upload (and goes on) and MAV_MISSION_ERROR after it; PX4 ignores it during its
upload and answers the last item again with its MISSION_ACK after it (`_unasked_item`).
`reply_delay_s` delays everything it sends (a slow link); `lose_upload_acks` drops that many
of its uploads' final MISSION_ACKs.
"""

from __future__ import annotations

import select
import socket
import struct
import threading
import time

from common.wire.mavlink import MAV, encoder, pack, parser
from common.wire.mission_items import MissionItem, item_from_message
from common.wire.mission_messages import item_message
from gcs import cli  # imported before any test captures the output (gcs.cli.console)

M = MAV
ARDUPILOT_CAPS = 0xFBEF  # what ArduCopter 4.7 announces (neither PARAM_ENCODE bit)
PX4_CAPS = 0xFBEF | M.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
HOME = (-35.3632621, 149.1652374, 584.25)  # ArduPilot's SITL home (alt: exact in float32)
_FORMATS = {1: "<B", 2: "<b", 3: "<H", 4: "<h", 5: "<I", 6: "<i"}
_RANGES = {1: (0, 255), 2: (-128, 127), 3: (0, 65535), 4: (-32768, 32767),
           5: (0, 2**32 - 1), 6: (-2**31, 2**31 - 1)}


# Four global items as ArduPilot keeps them (home at seq 0), for uploads of either firmware
PLAN_HOME_ITEMS = tuple(
    MissionItem(i, 0, 16, 0, 1, 0.0, 0.0, 0.0, 0.0, round(HOME[0] * 1e7) + 100 * i,
                round(HOME[1] * 1e7), 20.0) for i in range(4))


class _RawParamValue(M.MAVLink_param_value_message):
    """PARAM_VALUE with param_value's four bytes as given (PX4's bytewise integers)."""

    def __init__(self, name: str, raw: bytes, param_type: int, count: int, index: int):
        super().__init__(name.encode(), struct.unpack("<f", raw)[0], param_type, count, index)
        self._raw = raw

    def pack(self, mav, force_mavlink1: bool = False) -> bytes:
        body = self._raw + struct.pack("<HH16sB", self.param_count, self.param_index,
                                       self._param_id_raw, self.param_type)
        return self._pack(mav, self.crc_extra, body, force_mavlink1=force_mavlink1)


class ScriptedAutopilot:
    """`kind` "ardupilot" or "px4"; `params` name -> (value, MAV_PARAM_TYPE); `refuse`
    command -> (MAV_MISSION_RESULT, text or ""): an uploaded item with that command is
    refused. `home` None: it has no home (HOME_POSITION requests are refused). `mute`: a
    text it says to a MISSION_COUNT, after which it asks for no item."""

    def __init__(self, kind: str, params: dict[str, tuple[float, int]] | None = None,
                 refuse: dict[int, tuple[int, str]] | None = None,
                 home: tuple[float, float, float] | None = HOME, mute: str = "",
                 reply_delay_s: float = 0.0, lose_upload_acks: int = 0) -> None:
        self.kind = kind
        self.reply_delay_s = reply_delay_s
        self.lose_upload_acks = lose_upload_acks
        self._delayed: list[tuple[float, bytes]] = []  # (when, frame), in order
        self._last_count = 0  # the count of the last upload taken whole
        self.unasked_items = 0  # items it did not ask for (answered as its firmware does)
        self.mute = mute
        self.params = dict(params or {})
        self.names = list(self.params)
        self.refuse = dict(refuse or {})
        self.home = home
        self.mission: list[MissionItem] = []  # as the vehicle keeps it (wire seq)
        self.param_sets: list[tuple[str, int, bytes]] = []  # (name, type, raw) received
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.url = f"udpout:127.0.0.1:{self.port}"
        self.mav = encoder(1, M.MAV_COMP_ID_AUTOPILOT1)
        self.parser = parser()
        self._peer: tuple[str, int] | None = None
        self._upload: list[MissionItem] | None = None
        self._count = 0
        self.errors: list[BaseException] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="scripted-autopilot",
                                        daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ plumbing

    def _send(self, msg) -> None:
        if self._peer is None:
            return
        frame = pack(self.mav, msg)
        if self.reply_delay_s > 0.0:
            self._delayed.append((time.monotonic() + self.reply_delay_s, frame))
        else:
            self.sock.sendto(frame, self._peer)

    def _send_due(self) -> None:
        now = time.monotonic()
        while self._delayed and self._delayed[0][0] <= now and self._peer is not None:
            self.sock.sendto(self._delayed.pop(0)[1], self._peer)

    def _run(self) -> None:
        beat = 0.0
        autopilot = M.MAV_AUTOPILOT_ARDUPILOTMEGA if self.kind == "ardupilot" else \
            M.MAV_AUTOPILOT_PX4
        try:
            while not self._stop.is_set():
                if select.select([self.sock], [], [], 0.002 if self._delayed else 0.01)[0]:
                    data, self._peer = self.sock.recvfrom(65535)
                    for msg in self.parser.parse_buffer(data) or []:
                        if msg.get_type() != "BAD_DATA":
                            self._handle(msg)
                self._send_due()
                if time.monotonic() - beat > 0.1 and self._peer is not None:
                    beat = time.monotonic()
                    self._send(M.MAVLink_heartbeat_message(
                        M.MAV_TYPE_HEXAROTOR, autopilot,
                        M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 0, M.MAV_STATE_STANDBY, 3))
        except BaseException as exc:  # surfaced by close()
            self.errors.append(exc)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        self.sock.close()
        assert not self._thread.is_alive()
        assert not self.errors, self.errors

    # ------------------------------------------------------------------ messages

    def _handle(self, msg) -> None:
        kind = msg.get_type()
        if kind == "COMMAND_LONG":
            self._command(msg)
        elif kind.startswith("MISSION_"):
            self._mission_message(kind, msg)
        elif kind.startswith("PARAM_"):
            self._param_message(kind, msg)

    def _mission_message(self, kind: str, msg) -> None:
        if kind == "MISSION_COUNT" and self.mute:
            self._send(M.MAVLink_statustext_message(M.MAV_SEVERITY_WARNING,
                                                    self.mute.encode()))
        elif kind == "MISSION_COUNT":
            self._upload, self._count = [], msg.count
            self._request(0)
        elif kind in ("MISSION_ITEM_INT", "MISSION_ITEM"):
            self._item(item_from_message(msg))
        elif kind == "MISSION_REQUEST_LIST":
            self._send(M.MAVLink_mission_count_message(255, 0, len(self.mission), 0))
        elif kind in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
            self._answer_request(msg.seq)
        elif kind == "MISSION_CLEAR_ALL":
            self.mission = []
            self._send(M.MAVLink_mission_ack_message(255, 0, M.MAV_MISSION_ACCEPTED, 0))

    def _answer_request(self, seq: int) -> None:
        if 0 <= seq < len(self.mission):
            it = self.mission[seq]
            if self.kind == "ardupilot" and seq == 0 and self.home is not None:
                lat, lon, alt = self.home  # its own home, whatever was uploaded
                it = it._replace(frame=0, command=16, x=round(lat * 1e7),
                                 y=round(lon * 1e7), z=alt)
            self._send(item_message(self._as_stored(it), 255, 0))

    def _param_message(self, kind: str, msg) -> None:
        if kind == "PARAM_REQUEST_LIST":
            for i in range(len(self.names)):
                self._param_value(i)
        elif kind == "PARAM_REQUEST_READ":
            name = msg.param_id
            if msg.param_index >= 0 and msg.param_index < len(self.names):
                self._param_value(msg.param_index)
            elif name in self.params:
                self._param_value(self.names.index(name))
        elif kind == "PARAM_SET":
            self._param_set(msg)

    def _command(self, msg) -> None:
        result = M.MAV_RESULT_ACCEPTED
        if msg.command == M.MAV_CMD_REQUEST_MESSAGE and msg.param1 == 242:
            if self.home is None:
                result = M.MAV_RESULT_DENIED
            else:
                lat, lon, alt = self.home
                self._send(M.MAVLink_home_position_message(
                    round(lat * 1e7), round(lon * 1e7), round(alt * 1e3), 0, 0, 0,
                    [1, 0, 0, 0], 0, 0, 0))
        elif msg.command == M.MAV_CMD_REQUEST_MESSAGE and msg.param1 == 148:
            caps = ARDUPILOT_CAPS if self.kind == "ardupilot" else PX4_CAPS
            self._send(M.MAVLink_autopilot_version_message(
                caps, 0x04070000, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, 0))
        self._send(M.MAVLink_command_ack_message(msg.command, result))

    def _as_stored(self, it: MissionItem) -> MissionItem:
        """A global item as the firmware answers it: PX4 keeps only whether the altitude is
        relative and answers MISSION_REQUEST_INT in the _INT frames (mavlink_mission.cpp,
        format_mavlink_mission_item); ArduPilot answers in the plain frames (AP_Mission,
        mission_cmd_to_mavlink_int)."""
        plain = {5: 0, 6: 3, 11: 10}.get(it.frame, it.frame)
        if self.kind == "px4" and plain in (0, 3):
            return it._replace(frame={0: 5, 3: 6}[plain])
        if self.kind == "ardupilot":
            return it._replace(frame=plain)
        return it

    def _request(self, seq: int) -> None:
        self._send(M.MAVLink_mission_request_int_message(255, 0, seq, 0))

    def _unasked_item(self, item: MissionItem) -> None:
        """An item it did not ask for. ArduPilot: MAV_MISSION_INVALID_SEQUENCE while it
        receives (the upload goes on), MAV_MISSION_ERROR when it does not (GCS_Common.cpp
        handle_mission_item, MissionItemProtocol::handle_mission_item). PX4: ignored while
        it receives; after, the last item again is ACCEPTED again (its ACK was lost), any
        other MAV_MISSION_ERROR (mavlink_mission.cpp handle_mission_item_both)."""
        self.unasked_items += 1
        receiving = self._upload is not None
        if self.kind == "ardupilot":
            result = M.MAV_MISSION_INVALID_SEQUENCE if receiving else M.MAV_MISSION_ERROR
        elif receiving:
            return
        else:
            result = M.MAV_MISSION_ACCEPTED if item.seq == self._last_count - 1 else \
                M.MAV_MISSION_ERROR
        self._send(M.MAVLink_mission_ack_message(255, 0, result, 0))

    def _item(self, item: MissionItem) -> None:
        if self._upload is None or item.seq != len(self._upload):
            self._unasked_item(item)
            return
        refused = self.refuse.get(item.command)
        if refused is None and self.kind == "ardupilot" and item.frame == 1:
            refused = (M.MAV_MISSION_UNSUPPORTED_FRAME, "")
        if refused is not None:
            result, text = refused
            if text:
                self._send(M.MAVLink_statustext_message(M.MAV_SEVERITY_WARNING,
                                                        text.encode()))
            self._upload = None
            self._send(M.MAVLink_mission_ack_message(255, 0, result, 0))
            return
        self._upload.append(item)
        if len(self._upload) < self._count:
            self._request(len(self._upload))
            return
        self.mission, self._upload = self._upload, None
        self._last_count = self._count
        if self.lose_upload_acks > 0:
            self.lose_upload_acks -= 1
            return
        self._send(M.MAVLink_mission_ack_message(255, 0, M.MAV_MISSION_ACCEPTED, 0))

    # ------------------------------------------------------------------ parameters

    def _raw(self, value: float, param_type: int) -> bytes:
        if self.kind == "px4" and param_type in _FORMATS:
            return struct.pack(_FORMATS[param_type], int(value)).ljust(4, b"\0")
        return struct.pack("<f", value)

    def _param_value(self, i: int) -> None:
        name = self.names[i]
        value, param_type = self.params[name]
        self._send(_RawParamValue(name, self._raw(value, param_type), param_type,
                                  len(self.names), i))

    def _param_set(self, msg) -> None:
        name = msg.param_id
        raw = bytes(msg.get_msgbuf()[10:14]).ljust(4, b"\0")
        self.param_sets.append((name, msg.param_type, raw))
        if name not in self.params:
            return
        _old, param_type = self.params[name]
        if self.kind == "px4":
            if msg.param_type != param_type:
                self._send(M.MAVLink_statustext_message(
                    M.MAV_SEVERITY_ERROR, f"param types mismatch: {name}".encode()))
                self._param_value(self.names.index(name))
                return
            fmt = _FORMATS.get(param_type)
            value = float(struct.unpack(fmt, raw[:struct.calcsize(fmt)])[0]) if fmt else \
                float(struct.unpack("<f", raw)[0])
        else:  # ArduPilot: the float cast to the parameter's type, clamped to its range
            value = float(struct.unpack("<f", raw)[0])
            if param_type in _RANGES:
                lo, hi = _RANGES[param_type]
                value = float(min(max(int(value), lo), hi))
        self.params[name] = (value, param_type)
        self._param_value(self.names.index(name))


def gcs(capsys, vehicle: ScriptedAutopilot, *args: str) -> tuple[int, str, str]:
    """`gcs ARGS` against `vehicle` through the real entry point: (exit code, stdout,
    stderr)."""
    code = cli.main([*args, "--connect", vehicle.url, "--wait", "5"])
    out = capsys.readouterr()
    return code, out.out, out.err


class Companion:
    """Another component of the vehicle's system on its link (a companion computer, id 191,
    behind a router that merges it into the vehicle's link): while entered, sends its
    HEARTBEAT and `messages` every `period_s` from the vehicle's socket."""

    def __init__(self, vehicle: ScriptedAutopilot, messages: tuple = (),
                 period_s: float = 0.1, component: int = 191) -> None:
        self.vehicle = vehicle
        self.messages = (M.MAVLink_heartbeat_message(
            M.MAV_TYPE_ONBOARD_CONTROLLER, M.MAV_AUTOPILOT_INVALID, 0, 0,
            M.MAV_STATE_ACTIVE, 3), *messages)
        self.period_s = period_s
        self.mav = encoder(vehicle.mav.srcSystem, component)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="companion", daemon=True)

    def _run(self) -> None:
        while not self._stop.wait(self.period_s):
            peer = self.vehicle._peer
            if peer is not None:
                for msg in self.messages:
                    self.vehicle.sock.sendto(pack(self.mav, msg), peer)

    def __enter__(self) -> Companion:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
