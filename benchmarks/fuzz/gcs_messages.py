"""Messages for the FCU's GCS link with any field values: the value pools, float32 helpers,
and the signed, unsigned and wrongly signed encoders the sequences use."""

from __future__ import annotations

import functools
import hashlib
import math
import random
import struct
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

from benchmarks.fuzz.traffic import Traffic
from common.wire.mavlink import MAV, encoder, pack, parser, signing_timestamp
from common.wire.modes import Mode
from fcu.edge.gcs_server import HANDLED
from fcu.edge.telemetry import DEFAULT_INTERVALS_S, REQUESTABLE
from fcu.mission.codes import SUPPORTED_COMMANDS as MISSION_COMMANDS
from fcu.params import SPECS as PARAM_SPECS

M = MAV


MESSAGE_CLASSES = {kind: getattr(M, f"MAVLink_{kind.lower()}_message") for kind in HANDLED}
# pymavlink lists array_lengths in wire order (ordered_fieldnames), not in argument order
ARRAY_LENGTHS = {kind: dict(zip(cls.ordered_fieldnames, cls.array_lengths, strict=True))
                  for kind, cls in MESSAGE_CLASSES.items()}
FIELD_WEIGHTS = [3.0 if kind.startswith("COMMAND_") else 1.0 for kind in HANDLED]
INT_RANGES = {"int8_t": (-2**7, 2**7 - 1), "uint8_t": (0, 2**8 - 1),
              "int16_t": (-2**15, 2**15 - 1), "uint16_t": (0, 2**16 - 1),
              "int32_t": (-2**31, 2**31 - 1), "uint32_t": (0, 2**32 - 1),
              "int64_t": (-2**63, 2**63 - 1), "uint64_t": (0, 2**64 - 1)}
F32_MAX = 3.4028234663852886e38
F32_BELOW_2_31 = 2147483520.0  # the largest float32 below 2^31
SPECIAL_FLOATS = (0.0, -0.0, math.nan, math.inf, -math.inf, 1.0, -1.0, 0.5, -0.5, 2.0, 3.0,
                  4.0, 6.0, -2.0, 1e-45, -1e-45, 1.1754943508222875e-38, F32_MAX, -F32_MAX,
                  1e38, -1e38, 1e30, 1e10, 1e6, 2.0**31, -2.0**31, 2.0**32, 2.0**24,
                  2.0**24 + 2, 65535.0, 65536.0, 255.0, 256.0, 21196.0, F32_BELOW_2_31)
INT32_EXTREMES = (-2**31, 2**31 - 1, 0, 1, -1, 2**31 - 2, -2**31 + 1, 10**9, -10**9)
STREAM_IDS = tuple(sorted(DEFAULT_INTERVALS_S))
REQUESTABLE_IDS = tuple(sorted(REQUESTABLE))
NOT_ANSWERED_IDS = (M.MAVLINK_MSG_ID_STATUSTEXT, M.MAVLINK_MSG_ID_PARAM_VALUE,
                    M.MAVLINK_MSG_ID_COMMAND_ACK, M.MAVLINK_MSG_ID_MESSAGE_INTERVAL, 1234,
                    65535)
ODD_IDS = (-1.0, -0.0, 0.5, 148.5, 65535.0, 65536.0, 2.0**24 - 1, 2.0**24, 2.0**32, math.nan,
           math.inf, -math.inf, 1e38, -1e38)
# SET_MESSAGE_INTERVAL param2 (us): around int32 (2^31-1 is 2^31 as a float32), around the
# 1 kHz floor, the special values -1 (off) and 0 (default), and what is neither
INTERVALS_US = (F32_BELOW_2_31, 2.0**31 - 1, 2.0**31, 2.0**31 + 5, 2.0**32, 2.0**32 + 1,
                1e9, 1e10, 1e30, F32_MAX, -F32_MAX, math.inf, -math.inf, math.nan, -1.0, -2.0,
                -0.5, -1e-45, -0.0, 0.0, 1e-45, 0.4, 0.5, 0.6, 1.0, 999.0, 999.5, 1000.0,
                1001.0, 20000.0, 1e6, 16777217.0)
COMMANDS = (M.MAV_CMD_COMPONENT_ARM_DISARM, M.MAV_CMD_DO_SET_MODE, M.MAV_CMD_MISSION_START,
            M.MAV_CMD_DO_SET_MISSION_CURRENT, M.MAV_CMD_NAV_LAND,
            M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAV_CMD_GET_MESSAGE_INTERVAL,
            M.MAV_CMD_REQUEST_MESSAGE, M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
            M.MAV_CMD_NAV_TAKEOFF, 0, 1, 65535)
SET_IV, GET_IV = M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAV_CMD_GET_MESSAGE_INTERVAL
REQUEST, ARM = M.MAV_CMD_REQUEST_MESSAGE, M.MAV_CMD_COMPONENT_ARM_DISARM
SET_MODE = M.MAV_CMD_DO_SET_MODE
PARAM_NAMES = tuple(s.name for s in PARAM_SPECS)
ODD_PARAM_NAMES = (b"", b"\x00" * 16, b"X" * 16, b"mis_cruise_spd", b"MIS_CRUISE_SPD\x00X",
                   b"MIS_CRUISE_SPD ", b"DQ_KPR_X\xff", b"DQ_KPR_XYZ_ABCDE", b"\xff" * 16,
                   "DQ_KPR_\u00c9".encode())
PROBE_SYSID = 251  # the probes' system id: no other input comes from it
SENDERS = ((255, 190), (254, 190), (250, 1), (1, 1), (1, 190), (0, 0), (42, 158), (253, 0))
FUZZ_LINK_ID, WRONG_LINK_ID, RAW_LINK_ID, PROBE_LINK_ID = 7, 8, 9, 100  # signing streams


def f32(x: float) -> float:
    """`x` as the float32 the wire carries (inf beyond the float32 range)."""
    try:
        return float(struct.unpack("<f", struct.pack("<f", x))[0])
    except OverflowError:
        return math.copysign(math.inf, x)


def f32_step(x: float, up: bool) -> float:
    """The float32 next to `x` (finite) upwards or downwards."""
    bits = struct.unpack("<i", struct.pack("<f", x))[0]
    if x == 0.0:
        return 1e-45 if up else -1e-45
    bits += 1 if (x > 0) == up else -1
    return float(struct.unpack("<f", struct.pack("<i", bits))[0])


def describe(data: bytes) -> str:
    """What a datagram carries, for a person (frames it holds, else its bytes)."""
    p = parser()
    try:
        msgs = [m for m in p.parse_buffer(data) or [] if m.get_type() != "BAD_DATA"]
    except Exception:
        msgs = []
    if not msgs:
        return f"{len(data)} bytes {data[:24].hex()}{'...' if len(data) > 24 else ''}"
    return " + ".join(f"{m} from {m.get_srcSystem()}/{m.get_srcComponent()}" for m in msgs)


@dataclass
class Input:
    category: str
    frames: list[bytes]  # datagrams, sent in this order from one socket
    sequence: bool

Encoders = dict[tuple[int, int], MAV.MAVLink]  # by (system id, component id) of the sender


class GcsMessages:
    """Messages for the GCS link with any field values, encoded as a sender would (signed
    with `signing_key` when given, a few unsigned, wrongly signed and replayed). Seeded."""

    def __init__(self, seed: int, signing_key: bytes | None = None) -> None:
        self.rng = random.Random(seed)
        self.key = signing_key
        self.raw = Traffic("gcs", seed + 1)  # the non-destructive categories
        self._signed: Encoders = {}
        self._plain: Encoders = {}
        self._wrong: Encoders = {}
        self._wrong_key = self.rng.randbytes(32)
        self._replayable: deque[bytes] = deque(maxlen=256)
        self._raw_ts = signing_timestamp()

    # -- framing

    def _encoder(self, sender: tuple[int, int], cache: Encoders, key: bytes | None = None,
                 link_id: int = 0) -> MAV.MAVLink:
        mav = cache.get(sender)
        if mav is None:
            mav = cache[sender] = encoder(*sender)
            if key is not None:
                mav.signing.secret_key = key
                mav.signing.sign_outgoing = True
                mav.signing.link_id = link_id
                mav.signing.timestamp = signing_timestamp()
        return mav

    def _pack(self, msg: MAV.MAVLink_message, sender: tuple[int, int]) -> bytes:
        if self.key is None:
            return pack(self._encoder(sender, self._plain), msg)
        r = self.rng.random()
        if r < 0.02:  # unsigned: refused
            return pack(self._encoder(sender, self._plain), msg)
        if r < 0.04:  # another key: refused
            return pack(self._encoder(sender, self._wrong, self._wrong_key, WRONG_LINK_ID), msg)
        if r < 0.06 and self._replayable:  # a frame already sent: refused as a replay
            return self.rng.choice(self._replayable)
        data = pack(self._encoder(sender, self._signed, self.key, FUZZ_LINK_ID), msg)
        self._replayable.append(data)
        return data

    def _frame(self, msgid: int, payload: bytes, sender: tuple[int, int]) -> bytes:
        """A MAVLink 2 frame with a valid CRC (and signature) around any payload."""
        key = self.key
        signed = key is not None and self.rng.random() < 0.95
        header = struct.pack("<BBBBBBBHB", 0xFD, len(payload), 1 if signed else 0, 0,
                             self.rng.getrandbits(8), *sender, msgid & 0xFFFF, msgid >> 16)
        crc = M.x25crc(header[1:])
        crc.accumulate(payload)
        crc.accumulate(bytes([M.mavlink_map[msgid].crc_extra]))
        frame = header + payload + struct.pack("<H", crc.crc)
        if key is not None and signed:
            self._raw_ts += 1
            stamp = struct.pack("<BQ", RAW_LINK_ID, self._raw_ts)[:7]
            frame += stamp + hashlib.sha256(key + frame + stamp).digest()[:6]
        return frame

    def _sender(self) -> tuple[int, int]:
        if self.rng.random() < 0.85:
            return self.rng.choice(SENDERS)
        sysid = self.rng.randint(0, 255)
        return (sysid if sysid != PROBE_SYSID else 255), self.rng.randint(0, 255)

    # -- field values

    def _float(self) -> float:
        r = self.rng.random()
        if r < 0.55:
            return self.rng.choice(SPECIAL_FLOATS)
        if r < 0.75:
            return float(struct.unpack("<f", self.rng.randbytes(4))[0])  # any float32, NaNs too
        return self.rng.uniform(-1000.0, 1000.0)

    def _int(self, ftype: str) -> int:
        lo, hi = INT_RANGES[ftype]
        if self.rng.random() < 0.5:
            return self.rng.choice((lo, hi, 0, 1, lo + 1, hi - 1, (lo + hi) // 2 + 1))
        return self.rng.randint(lo, hi)

    def _chars(self, n: int) -> bytes:
        r = self.rng.random()
        if r < 0.4:
            return self.rng.choice(PARAM_NAMES).encode()
        if r < 0.55:
            return self.rng.choice(ODD_PARAM_NAMES)
        if r < 0.75:
            return bytes(self.rng.randint(1, 255) for _ in range(n))
        return self.rng.randbytes(self.rng.randint(0, n))

    def _int32(self, x: float) -> int:
        if math.isfinite(x) and -2**31 <= x <= 2**31 - 1:
            return int(x)
        return self.rng.choice(INT32_EXTREMES)

    def _target(self) -> tuple[int, int]:
        r = self.rng.random()
        ts = 1 if r < 0.85 else 0 if r < 0.95 else self.rng.choice((2, 255, PROBE_SYSID))
        tc = 1 if self.rng.random() < 0.75 else self.rng.choice((0, 0, 190, 255))
        return ts, tc

    def random_message(self, kind: str) -> MAV.MAVLink_message:
        """`kind` with random field values, biased to the FCU's ids and commands."""
        cls, lengths, r = MESSAGE_CLASSES[kind], ARRAY_LENGTHS[kind], self.rng
        values: list[object] = []
        for name, ftype in zip(cls.fieldnames, cls.fieldtypes, strict=True):
            n = lengths[name]
            if ftype == "char":
                values.append(self._chars(n))
                continue
            one: Callable[[], object]
            if ftype in ("float", "double"):
                one = self._float
            else:
                one = functools.partial(self._int, ftype)
            if name == "target_system" and r.random() < 0.85:
                value: object = r.choice((1, 1, 1, 0))
            elif name == "target_component" and r.random() < 0.8:
                value = r.choice((1, 1, 0))
            elif name == "command" and r.random() < 0.8:
                value = r.choice(sorted(MISSION_COMMANDS) if kind.startswith("MISSION")
                                 else COMMANDS)
            elif name == "mission_type" and r.random() < 0.7:
                value = 0
            elif name in ("frame", "coordinate_frame") and r.random() < 0.5:
                value = M.MAV_FRAME_LOCAL_NED
            elif name == "custom_mode" and r.random() < 0.5:
                value = r.choice([m.custom_mode for m in Mode])
            else:
                value = [one() for _ in range(n)] if n else one()
            values.append(value)
        return cls(*values)

    # -- commands

    def _cmd(self, command: int, *params: float, as_int: bool | None = None
             ) -> MAV.MAVLink_message:
        p = [*params, *(0.0,) * (7 - len(params))]
        ts, tc = self._target()
        if as_int is None:
            as_int = self.rng.random() < 0.2
        if as_int:
            return M.MAVLink_command_int_message(
                ts, tc, self.rng.choice((0, 1, 3, 5, 255)), command, 0, 0, *p[:4],
                self._int32(p[4]), self._int32(p[5]), p[6])
        return M.MAVLink_command_long_message(ts, tc, command,
                                              self.rng.choice((0, 0, 0, 1, 255)), *p)

    def _msg_id(self) -> float:
        r = self.rng.random()
        if r < 0.5:
            return float(self.rng.choice(STREAM_IDS))
        if r < 0.62:
            return float(self.rng.choice(REQUESTABLE_IDS + NOT_ANSWERED_IDS))
        if r < 0.85:
            return self.rng.choice(ODD_IDS)
        return float(self.rng.randint(0, 2**24 - 1))

    def _interval(self) -> float:
        r = self.rng.random()
        if r < 0.7:
            return self.rng.choice(INTERVALS_US)
        if r < 0.85:
            return self._float()
        return float(self.rng.randint(-2, 2**31 + 10))
