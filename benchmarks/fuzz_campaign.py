"""Hostile-input campaign against running processes, while a real flight goes on.

A real-time Case I flight (sitl + fcu processes, mission uploaded with the mission protocol,
armed, MISSION_START) is hit on one port at a time with at least 100,000 inputs:

    gcs   the FCU's first GCS link (`--gcs udpin:127.0.0.1:PORT`: it reads from any sender),
          beside the ground station's own session on the same port
    sim   the FCU's simulator link: through a relay on the link (as a corrupting wire or a
          man in the middle would), plus datagrams sent straight to the FCU's ephemeral sim
          port ("fcu: sim port N") from other sockets
    sitl  the simulator's port (udpin)
    gcs-signed  the GCS link again, the same inputs, with MAVLink 2 signing required

The FCU has two GCS links: the first is attacked, the second (`--gcs
udpout:127.0.0.1:PORT2`) only listens. Nothing is ever sent to it; a listener records every
datagram it brings with its kernel arrival time. Its HEARTBEAT must never stop (no gap of
`--gap-limit`, 2.5 s, or more over the whole flight) and its messages per second show that
no stream went unbounded, whatever happened on the first link.

Non-destructive inputs (every port): random datagrams, valid frames cut short, valid frames
with 1-3 bits flipped (CRC-16 catches every such error), valid frames for or from other
system ids that the target must ignore, and floods (bursts of valid frames at full speed).
A baseline flight without hostile input gives the deadline misses to compare with.

Then, on the GCS ports, in the same flight, a second campaign of `--inputs` inputs that the
FCU reads and obeys, so that the flight's state changes under it: SEQUENCES, where what one
message sets the next one reads,

    set_get          SET_MESSAGE_INTERVAL with extreme, boundary, NaN, +-inf or negative
                     intervals (and ids), then GET_MESSAGE_INTERVAL of the same id
    request_stream   REQUEST_MESSAGE for every requestable id (and some that are not), then
                     SET_MESSAGE_INTERVAL of every stream (all fast, slow, off, default, any)
    mission          MISSION_COUNT then items with extreme fields; uploads cut short or
                     aborted (MISSION_ACK, CLEAR_ALL, another GCS's COUNT, COUNT 0);
                     downloads; set current; valid missions uploaded, armed and started
    param            PARAM_SET then PARAM_REQUEST_READ (by name or index), extreme values
    mode_arm         arm/disarm (forced too), modes (DO_SET_MODE, SET_MODE, NAV_LAND,
                     MISSION_START), offboard set-point streams then OFFBOARD

and single inputs: every message type the FCU handles with random field values (extremes of
each integer type, NaN, +-inf, 0, huge floats, random float32 bit patterns, any bytes in
names), frames with a valid CRC around random payloads of any length, several frames in one
datagram, damaged frames, and the non-destructive categories above. On the signed link they
are signed (a few unsigned, wrongly signed or replayed). The simulator runs in real time
beside the FCU, so arming, mission starts and offboard act on a live state.

Probes check the answers from a socket of their own, each after a sync (the FCU has read
everything sent before): the interval GET reads is the one SET put in force (or the old one
when refused); a parameter read back is the value set (or the old one) and within its range;
every requestable id is answered and no other; with link 1's streams off, some asked at
1 kHz stay within the link budget, and all go back to their defaults; HEARTBEAT turned off
on link 1 stops there and goes on on link 2;
(signed link) a replayed frame is refused, and a frame with a wrong signature cannot lock a
signed stream out.

Printed per flight: inputs sent by category, crashes (a process that exited), the FCU's
deadline misses, rejected bytes and ignored messages (`--stats`), the simulator's rejected
bytes, SYS_STATUS errors_comm, the largest ERR_POS and heartbeat gap during the attack,
whether the mission kept flying, the listening link, the sequence campaign and its probes.
At the end, one summary per port: inputs sent, how many in sequences, whether the FCU was
alive (and its exit code), its `internal_errors`, `ignored_messages` and `rejected_bytes`,
the longest HEARTBEAT gap on the listening link and the messages per second it received.
Exit status 0 only when, on every port, the FCU survived with internal_errors == 0, the
listening link's HEARTBEAT gap stayed below the bound, every probe agreed, and the flight
kept its mission under the non-destructive attack.

    .venv/bin/python benchmarks/fuzz_campaign.py                 # 100,000 inputs per port
    .venv/bin/python benchmarks/fuzz_campaign.py --inputs 20000 --ports gcs,sitl --seed 7
    .venv/bin/python benchmarks/fuzz_campaign.py --ports gcs --seq-rate 4000 --out DIR
"""

from __future__ import annotations

import argparse
import functools
import hashlib
import itertools
import json
import math
import random
import re
import secrets
import select
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:  # run as a script: the repository's packages and tests/
    sys.path.insert(0, str(ROOT))

from common.config import load_scenario  # noqa: E402
from common.links import free_port  # noqa: E402
from common.mavlink import MAV, encoder, pack, parser, signing_timestamp  # noqa: E402
from common.mission_items import local_xy  # noqa: E402
from common.modes import Mode  # noqa: E402
from common.simlink import (  # noqa: E402
    ActuatorControls,
    Odometry,
    pack_actuator_controls,
    pack_odometry,
)
from fcu.gcs_server import HANDLED  # noqa: E402
from fcu.mission.codes import SUPPORTED_COMMANDS as MISSION_COMMANDS  # noqa: E402
from fcu.params import SPECS as PARAM_SPECS  # noqa: E402
from fcu.telemetry import (  # noqa: E402
    DEFAULT_INTERVALS_S,
    LINK_BUDGET_MSG_S,
    MAX_INTERVAL_US,
    MIN_INTERVAL_S,
    REQUESTABLE,
)
from gcs.mission_client import upload  # noqa: E402
from gcs.scenario_mission import scenario_mission  # noqa: E402
from gcs.session import Session  # noqa: E402
from tests.udp_proxy import Impairment, UdpProxy  # noqa: E402

M = MAV
SCENARIO = ROOT / "config" / "scenarios" / "case1_figure8.toml"
VEHICLE = ROOT / "config" / "vehicles" / "hexa_tilted.toml"
PID = ROOT / "config" / "gains" / "pid_eq30.toml"
PORTS = ("gcs", "sim", "sitl")
CAMPAIGN_PORTS = (*PORTS, "gcs-signed")  # the GCS link again, with MAVLink 2 signing
MIX = (("random", 0.30), ("truncated", 0.20), ("bitflip", 0.25), ("foreign", 0.15),
       ("flood", 0.10))
FLOOD_BURST = 500
ERR_POS_LIMIT_M = 0.1
GAP_LIMIT_S = 2.5  # the listening link's HEARTBEAT (1 Hz) may never pause this long


# ----------------------------------------------------------------------------------------
# Hostile inputs
# ----------------------------------------------------------------------------------------


class Traffic:
    """Hostile datagrams for one target: "gcs" (the FCU's MAVLink GCS side), "sim" (the
    FCU's simulator side) or "sitl" (the simulator). Seeded."""

    def __init__(self, target: str, seed: int = 0) -> None:
        if target not in PORTS:
            raise ValueError(target)
        self.target = target
        self.rng = random.Random(seed)
        self._mavs: dict[int, MAV.MAVLink] = {}
        self._seq = 0
        # MIX gives shares of the inputs; a flood pick sends FLOOD_BURST of them at once
        self._categories = [c for c, _ in MIX]
        self._weights = [w / (FLOOD_BURST if c == "flood" else 1) for c, w in MIX]

    # -- building blocks

    def _mav(self, sysid: int, compid: int = M.MAV_COMP_ID_MISSIONPLANNER) -> MAV.MAVLink:
        key = sysid << 8 | compid
        mav = self._mavs.get(key)
        if mav is None:
            mav = self._mavs[key] = encoder(sysid, compid)
        return mav

    def _f(self) -> float:
        r = self.rng
        return r.choice([0.0, 1.0, -1.0, math.nan, math.inf, 3.4e38, 1e-45]) \
            if r.random() < 0.2 else r.uniform(-10.0, 10.0)

    def _odometry(self, sysid: int = 1) -> bytes:
        r = self.rng
        odo = Odometry(r.getrandbits(40), (r.uniform(-5, 5), r.uniform(-5, 5), -r.uniform(0, 10)),
                       (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
        self._seq = (self._seq + 1) & 0xFF
        return pack_odometry(odo, self._seq, sysid, M.MAV_COMP_ID_PERIPHERAL)

    def _controls(self, sysid: int = 1) -> bytes:
        r = self.rng
        a = ActuatorControls(r.getrandbits(40), tuple(r.uniform(0, 1) for _ in range(16)),
                             r.choice([0, M.MAV_MODE_FLAG_SAFETY_ARMED]), 1)
        self._seq = (self._seq + 1) & 0xFF
        return pack_actuator_controls(a, self._seq, sysid, M.MAV_COMP_ID_AUTOPILOT1)

    def _hil_sensor(self, sysid: int) -> bytes:
        msg = M.MAVLink_hil_sensor_message(self.rng.getrandbits(40),
                                           *(self._f() for _ in range(13)), 0x1A3F, 0)
        return pack(self._mav(sysid, M.MAV_COMP_ID_PERIPHERAL), msg)

    def _heartbeat(self, sysid: int, kind: int = M.MAV_TYPE_GCS) -> bytes:
        msg = M.MAVLink_heartbeat_message(kind, M.MAV_AUTOPILOT_INVALID, 0, 0,
                                          M.MAV_STATE_ACTIVE, 3)
        return pack(self._mav(sysid), msg)

    def _gcs_message(self, target_system: int) -> bytes:
        """A command or request of the kinds a ground station sends, to `target_system`."""
        r = self.rng
        t = (target_system, r.choice([0, 1]))
        kind = r.randrange(8)
        if kind == 0:
            msg = M.MAVLink_command_long_message(*t, M.MAV_CMD_COMPONENT_ARM_DISARM, 0,
                                                 r.choice([0.0, 1.0]), 21196.0, 0, 0, 0, 0, 0)
        elif kind == 1:
            msg = M.MAVLink_command_long_message(*t, M.MAV_CMD_DO_SET_MODE, 0, 1.0,
                                                 r.choice([4.0, 6.0]), r.choice([3.0, 6.0]),
                                                 0, 0, 0, 0)
        elif kind == 2:
            msg = M.MAVLink_command_long_message(*t, M.MAV_CMD_NAV_LAND, 0, *(0.0,) * 7)
        elif kind == 3:
            msg = M.MAVLink_param_set_message(*t, b"MIS_CRUISE_SPD", self._f(),
                                              M.MAV_PARAM_TYPE_REAL32)
        elif kind == 4:
            msg = M.MAVLink_mission_count_message(*t, r.randint(0, 500), 0)
        elif kind == 5:
            msg = M.MAVLink_mission_clear_all_message(*t, 0)
        elif kind == 6:
            msg = M.MAVLink_set_position_target_local_ned_message(
                0, *t, M.MAV_FRAME_LOCAL_NED, 0, *(self._f() for _ in range(11)))
        else:
            msg = M.MAVLink_command_int_message(*t, 0, M.MAV_CMD_MISSION_START, 0, 0,
                                                *(0.0,) * 4, 0, 0, 0.0)
        return pack(self._mav(r.randint(1, 255)), msg)

    def valid_frame(self) -> bytes:
        """A valid frame of what the target reads, from and for the systems it serves (used
        only as the base of damaged frames: never sent whole)."""
        if self.target == "gcs":
            return self._gcs_message(1)
        if self.target == "sim":
            return self._odometry(1) if self.rng.random() < 0.8 else self._hil_sensor(1)
        return self._controls(1)

    def foreign_frame(self) -> bytes:
        """A valid frame the target must ignore: for another system, or a message of another
        system that the target has no use for."""
        r = self.rng
        other = r.randint(2, 254)
        if self.target == "gcs":
            return self._gcs_message(other)
        if r.random() < 0.5:
            return self._hil_sensor(other)
        return self._heartbeat(other, M.MAV_TYPE_HEXAROTOR)

    def flood_frame(self) -> bytes:
        """What a flood is made of: valid frames the target reads and drops cheaply."""
        r = self.rng
        if self.target == "gcs":
            return self._heartbeat(r.randint(200, 250)) if r.random() < 0.5 else \
                self._gcs_message(r.randint(2, 254))
        if self.target == "sim":
            return self._hil_sensor(1)
        return self._heartbeat(r.randint(2, 254), M.MAV_TYPE_HEXAROTOR)

    # -- categories

    def random_datagram(self) -> bytes:
        r = self.rng
        n = r.randint(1, 300)
        if r.random() < 0.5:
            return r.randbytes(n)
        # rich in start markers and plausible header bytes
        return bytes(r.choice((0xFD, 0xFD, 0xFE, 0x00, 0xFF, 0x4B, 0x01, 0x5D, r.getrandbits(8)))
                     for _ in range(n))

    def truncated(self) -> bytes:
        frame = self.valid_frame()
        return frame[:self.rng.randint(1, len(frame) - 1)]

    def bitflip(self) -> bytes:
        """1 to 3 flipped bits: CRC-16/MCRF4XX detects every such error in these lengths."""
        data = bytearray(self.valid_frame())
        for bit in self.rng.sample(range(8 * len(data)), self.rng.randint(1, 3)):
            data[bit // 8] ^= 1 << (bit % 8)
        return bytes(data)

    def next(self) -> tuple[str, list[bytes]]:
        """The next input's category and its datagrams (a flood is a burst of them)."""
        category = self.rng.choices(self._categories, self._weights)[0]
        if category == "random":
            return category, [self.random_datagram()]
        if category == "truncated":
            return category, [self.truncated()]
        if category == "bitflip":
            return category, [self.bitflip()]
        if category == "foreign":
            return category, [self.foreign_frame()]
        return category, [self.flood_frame() for _ in range(FLOOD_BURST)]


def blast(traffic: Traffic, send: Callable[[bytes, str], None], n: int, rate: float,
          counts: Counter, stop: threading.Event | None = None) -> None:
    """Send `n` inputs at about `rate` per second on average (floods go out at full speed
    within their burst). `send(data, category)`."""
    t0 = time.monotonic()
    sent = 0
    while sent < n and not (stop is not None and stop.is_set()):
        category, datagrams = traffic.next()
        for data in datagrams[:n - sent]:
            send(data, category)
            counts[category] += 1
            sent += 1
        ahead = sent / rate - (time.monotonic() - t0)
        if ahead > 0.002:
            time.sleep(ahead)


# ----------------------------------------------------------------------------------------
# Inputs the FCU obeys: sequences and any field values (the GCS ports' second campaign)
# ----------------------------------------------------------------------------------------

_CLASSES = {kind: getattr(M, f"MAVLink_{kind.lower()}_message") for kind in HANDLED}
# pymavlink lists array_lengths in wire order (ordered_fieldnames), not in argument order
_ARRAY_LENGTHS = {kind: dict(zip(cls.ordered_fieldnames, cls.array_lengths, strict=True))
                  for kind, cls in _CLASSES.items()}
_FIELD_WEIGHTS = [3.0 if kind.startswith("COMMAND_") else 1.0 for kind in HANDLED]
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
SEQUENCE_KINDS = ("set_get", "request_stream", "mission", "param", "mode_arm")
# picks (not inputs): a sequence is several inputs, a flood FLOOD_BURST of them; about two
# thirds of the inputs end up in sequences
SEQUENCE_MIX = (("set_get", 10.0), ("request_stream", 0.5), ("mission", 3.0), ("param", 8.0),
                ("mode_arm", 4.0), ("field", 30.0), ("payload", 8.0), ("multi", 3.0),
                ("damaged", 6.0), ("random", 5.0), ("truncated", 3.0), ("bitflip", 3.0),
                ("foreign", 3.0), ("flood", 0.01))
PROBE_SYSID = 251  # the probes' system id: no other input comes from it
SENDERS = ((255, 190), (254, 190), (250, 1), (1, 1), (1, 190), (0, 0), (42, 158), (253, 0))
FUZZ_LINK_ID, WRONG_LINK_ID, RAW_LINK_ID, PROBE_LINK_ID = 7, 8, 9, 100  # signing streams


def f32(x: float) -> float:
    """`x` as the float32 the wire carries (inf beyond the float32 range)."""
    try:
        return struct.unpack("<f", struct.pack("<f", x))[0]
    except OverflowError:
        return math.copysign(math.inf, x)


def f32_step(x: float, up: bool) -> float:
    """The float32 next to `x` (finite) upwards or downwards."""
    bits = struct.unpack("<i", struct.pack("<f", x))[0]
    if x == 0.0:
        return 1e-45 if up else -1e-45
    bits += 1 if (x > 0) == up else -1
    return struct.unpack("<f", struct.pack("<i", bits))[0]


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


class GcsSequences:
    """Inputs for the FCU's GCS link that it reads and obeys: sequences and single messages
    with any field values (module docstring). Seeded; signed with `signing_key` when given
    (with a few unsigned, wrongly signed and replayed frames)."""

    def __init__(self, seed: int, signing_key: bytes | None = None) -> None:
        self.rng = random.Random(seed)
        self.key = signing_key
        self.raw = Traffic("gcs", seed + 1)  # the non-destructive categories
        self._signed: dict[tuple[int, int], MAV.MAVLink] = {}
        self._plain: dict[tuple[int, int], MAV.MAVLink] = {}
        self._wrong: dict[tuple[int, int], MAV.MAVLink] = {}
        self._wrong_key = self.rng.randbytes(32)
        self._replayable: deque[bytes] = deque(maxlen=256)
        self._raw_ts = signing_timestamp()
        self._names = [c for c, _ in SEQUENCE_MIX]
        self._weights = [w for _, w in SEQUENCE_MIX]

    # -- framing

    def _encoder(self, sender: tuple[int, int], cache: dict, key: bytes | None = None,
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
            return struct.unpack("<f", self.rng.randbytes(4))[0]  # any float32, NaNs too
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
        cls, lengths, r = _CLASSES[kind], _ARRAY_LENGTHS[kind], self.rng
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

    def _mode_command(self) -> MAV.MAVLink_message:
        r = self.rng.random()
        if r < 0.6:
            main, sub = self.rng.choice(list(Mode)).value
            p = (self.rng.choice((1.0, 1.0, 129.0, 217.0, 0.0)), float(main), float(sub))
        elif r < 0.8:
            p = (self._float(), self._float(), self._float())
        else:
            p = (1.0, self.rng.choice((3.0, 0.0, 1.0, 2.0, 5.0, 7.0, 255.0, 256.0, -1.0)),
                 self.rng.choice((0.0, 1.0, 2.0, 5.0, 7.0, 255.0, math.nan)))
        return self._cmd(SET_MODE, *p)

    # -- sequences

    def set_get(self) -> list[bytes]:
        s, r = self._sender(), self.rng
        msg_id = self._msg_id()
        out = []
        if r.random() < 0.2:
            out.append(self._cmd(GET_IV, msg_id))
        extra = [self._float() for _ in range(5)] if r.random() < 0.2 else []
        out.append(self._cmd(SET_IV, msg_id, self._interval(), *extra))
        out.append(self._cmd(GET_IV, msg_id if r.random() < 0.9 else self._msg_id()))
        if r.random() < 0.1:
            out.append(self._cmd(SET_IV, msg_id, 0.0))  # back to the default
        return [self._pack(m, s) for m in out]

    def request_stream(self) -> list[bytes]:
        s, r = self._sender(), self.rng
        ids = [*REQUESTABLE_IDS, *r.sample(NOT_ANSWERED_IDS, 3), r.randint(0, 2**24 - 1)]
        r.shuffle(ids)
        out = [self._cmd(REQUEST, float(i),
                         *([self._float() for _ in range(6)] if r.random() < 0.2 else []))
               for i in ids]
        if r.random() < 0.5:
            out.append(self._cmd(M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
                                 r.choice((1.0, 0.0, math.nan, -1.0, F32_MAX))))
        how = r.choice(("fast", "fast", "slow", "off", "default", "any"))
        fixed = {"fast": 1.0, "slow": 1e6, "off": -1.0, "default": 0.0}.get(how)
        for i in r.sample(STREAM_IDS, len(STREAM_IDS)):
            out.append(self._cmd(SET_IV, float(i), self._interval() if fixed is None else fixed))
        if r.random() < 0.5:
            out += [self._cmd(GET_IV, float(i)) for i in STREAM_IDS]
        return [self._pack(m, s) for m in out]

    def _valid_item(self, seq: int) -> dict:
        r = self.rng
        cmd = r.choice(sorted(MISSION_COMMANDS))
        f = {"seq": seq, "frame": M.MAV_FRAME_LOCAL_NED, "command": cmd,
             "current": int(seq == 0), "autocontinue": 1, "param1": 0.0, "param2": 0.0,
             "param3": 0.0, "param4": math.nan, "x": local_xy(r.uniform(-20, 20)),
             "y": local_xy(r.uniform(-20, 20)), "z": -r.uniform(1.0, 10.0)}
        if cmd == M.MAV_CMD_NAV_TAKEOFF:
            f.update(param2=r.choice((0.0, r.uniform(1.0, 10.0))), x=0, y=0)
        elif cmd in (M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_LOITER_TIME):
            f.update(param1=r.uniform(0.0, 3.0))
        elif cmd == M.MAV_CMD_NAV_LAND:
            f.update(z=0.0)
        elif cmd == M.MAV_CMD_WAYPOINT_USER_1:  # pose keyframe
            f.update(param1=r.uniform(0.5, 5.0), param2=r.uniform(-0.5, 0.5),
                     param3=r.uniform(-0.5, 0.5), param4=r.uniform(-0.5, 0.5))
        else:  # figure eight
            f.update(param1=r.uniform(0.1, 3.0), param2=r.uniform(5.0, 30.0),
                     param3=r.uniform(-1.0, 1.0), param4=r.uniform(-1.0, 1.0), z=1.0)
        return f

    def _extreme(self, name: str) -> object:
        if name in ("x", "y"):
            return self.rng.choice(INT32_EXTREMES)
        if name.startswith("param") or name == "z":
            return self._float()
        return self._int("uint16_t" if name in ("seq", "command") else "uint8_t")

    def _item(self, seq: int, ts: int, tc: int, mission_type: int) -> MAV.MAVLink_message:
        r = self.rng
        if r.random() < 0.5:
            f = self._valid_item(seq)
            for _ in range(r.choice((0, 0, 1, 1, 2))):
                name = r.choice(list(f))
                f[name] = self._extreme(name)
        else:
            msg = self.random_message("MISSION_ITEM_INT")
            f = {name: getattr(msg, name) for name in msg.fieldnames
                 if name not in ("target_system", "target_component", "mission_type")}
            f["seq"] = seq
        if r.random() < 0.25:  # legacy MISSION_ITEM: x, y as floats in the frame's unit
            x = f["x"] / 1e4 if r.random() < 0.6 else self._float()
            y = f["y"] / 1e4 if r.random() < 0.6 else self._float()
            return M.MAVLink_mission_item_message(
                ts, tc, f["seq"], f["frame"], f["command"], f["current"], f["autocontinue"],
                f["param1"], f["param2"], f["param3"], f["param4"], x, y, f["z"],
                mission_type)
        return M.MAVLink_mission_item_int_message(
            ts, tc, f["seq"], f["frame"], f["command"], f["current"], f["autocontinue"],
            f["param1"], f["param2"], f["param3"], f["param4"], f["x"], f["y"], f["z"],
            mission_type)

    def _mission_target(self) -> tuple[int, int]:
        r = self.rng.random()
        ts = 1 if r < 0.85 else 0 if r < 0.95 else 2
        tc = 1 if self.rng.random() < 0.7 else self.rng.choice((0, 0, 0, 190))
        return ts, tc

    def _mission_type(self) -> int:
        return 0 if self.rng.random() < 0.9 else self.rng.choice((1, 2, 3, 255))

    def mission(self) -> list[bytes]:
        variant = self.rng.choices(("upload", "download", "current", "fly"), (6, 2, 1, 2))[0]
        s = self._sender() if variant != "fly" else self.rng.choice(SENDERS[:3])
        return [self._pack(m, s) for m in getattr(self, f"_mission_{variant}")()]

    def _mission_upload(self) -> list[MAV.MAVLink_message]:
        r = self.rng
        ts, tc = self._mission_target()
        mt = self._mission_type()
        count = r.choice((1, 2, 3, 4, 5, 8, 12)) if r.random() < 0.75 else \
            r.choice((0, 499, 500, 501, 65535, r.randint(0, 65535)))
        out = [M.MAVLink_mission_count_message(ts, tc, count, mt)]
        n = count if count <= 20 or (count <= 500 and r.random() < 0.05) else r.randint(0, 20)
        if r.random() < 0.3:
            n = r.randint(0, max(0, n - 1))  # cut short: the FCU re-requests, then gives up
        for i in range(n):
            seq = i
            if r.random() < 0.08:  # out of sequence, duplicate, beyond the count
                seq = r.choice((i + 1, max(i - 1, 0), 65535, count, r.randint(0, 65535)))
            out.append(self._item(seq, ts, tc, mt))
        end = r.choices(("none", "ack", "other_count", "clear", "request_list", "request",
                         "count0", "count_again"), (8, 2, 2, 1, 1, 1, 1, 1))[0]
        if end == "ack":  # the GCS cancels (any result)
            out.append(M.MAVLink_mission_ack_message(ts, tc, self._int("uint8_t"), mt))
        elif end == "other_count":  # another GCS starts an upload meanwhile
            out.insert(r.randint(1, len(out)), M.MAVLink_mission_count_message(
                ts, tc, r.choice((1, 3, 500)), mt))
        elif end == "clear":
            out.insert(r.randint(1, len(out)), M.MAVLink_mission_clear_all_message(
                ts, tc, self._mission_type()))
        elif end == "request_list":
            out.insert(r.randint(1, len(out)), M.MAVLink_mission_request_list_message(
                ts, tc, mt))
        elif end == "request":
            out.append(M.MAVLink_mission_request_int_message(ts, tc, r.choice((0, 65535)), mt))
        elif end == "count0":
            out.append(M.MAVLink_mission_count_message(ts, tc, 0, mt))
        elif end == "count_again":
            out.append(out[0])
        return out

    def _mission_download(self) -> list[MAV.MAVLink_message]:
        r = self.rng
        ts, tc = self._mission_target()
        mt = self._mission_type()
        out = [M.MAVLink_mission_request_list_message(ts, tc, mt)]
        for _ in range(r.randint(1, 5)):
            seq = r.choice((0, 1, 2, 3, 499, 500, 65535, r.randint(0, 65535)))
            cls = r.choice((M.MAVLink_mission_request_int_message,
                            M.MAVLink_mission_request_message))
            out.append(cls(ts, tc, seq, mt if r.random() < 0.8 else self._mission_type()))
        if r.random() < 0.3:
            cls = r.choice((M.MAVLink_mission_write_partial_list_message,
                            M.MAVLink_mission_request_partial_list_message))
            out.append(cls(ts, tc, self._int("int16_t"), self._int("int16_t"), mt))
        out.append(M.MAVLink_mission_ack_message(ts, tc, r.choice((0, 0, 1, 255)), mt))
        return out

    def _mission_current(self) -> list[MAV.MAVLink_message]:
        r = self.rng
        ts, tc = self._mission_target()
        out = [M.MAVLink_mission_set_current_message(
            ts, tc, r.choice((0, 1, 2, 3, 500, 65535, r.randint(0, 65535))))]
        out.append(self._cmd(M.MAV_CMD_DO_SET_MISSION_CURRENT, r.choice(
            (0.0, 1.0, 3.0, -1.0, 0.5, 65535.0, 65536.0, math.nan, math.inf, F32_MAX))))
        out.append(self._cmd(M.MAV_CMD_MISSION_START, self._float() if r.random() < 0.5
                             else r.choice((0.0, 1.0, 2.0)), self._float()))
        r.shuffle(out)
        return out

    def _mission_fly(self) -> list[MAV.MAVLink_message]:
        """A valid mission (takeoff, then waypoints, keyframes, a figure or a landing),
        armed and started: the vehicle flies it."""
        r = self.rng
        items = [self._valid_item(0)]
        items[0].update(command=M.MAV_CMD_NAV_TAKEOFF, param1=0.0, param2=0.0, param4=math.nan,
                        x=0, y=0, z=-r.uniform(1.5, 5.0))
        for seq in range(1, r.randint(2, 5)):
            items.append(self._valid_item(seq))
        out = [M.MAVLink_mission_count_message(1, 1, len(items), 0)]
        out += [M.MAVLink_mission_item_int_message(
            1, 1, f["seq"], f["frame"], f["command"], f["current"], f["autocontinue"],
            f["param1"], f["param2"], f["param3"], f["param4"], f["x"], f["y"], f["z"], 0)
            for f in items]
        out.append(self._cmd(ARM, 1.0))
        if r.random() < 0.7:
            out.append(self._cmd(M.MAV_CMD_MISSION_START, 0.0, float(len(items) - 1)))
        else:
            out.append(self._cmd(SET_MODE, 1.0, 4.0, 4.0))  # AUTO.MISSION
        if r.random() < 0.3:
            out.append(self._cmd(M.MAV_CMD_DO_SET_MISSION_CURRENT,
                                 float(r.randint(0, len(items)))))
        return out

    def _param_value(self, name: bytes) -> float:
        spec = next((s for s in PARAM_SPECS if s.name.encode() == name), None)
        r = self.rng
        if spec is not None and r.random() < 0.5:
            return r.choice((spec.lo, spec.hi, f32_step(spec.lo, up=False),
                             f32_step(spec.hi, up=True), (spec.lo + spec.hi) / 2,
                             r.uniform(spec.lo, spec.hi), spec.lo - 1.0, spec.hi * 2.0, 0.5))
        return self._float()

    def param(self) -> list[bytes]:
        s, r = self._sender(), self.rng
        ts, tc = self._target()
        name = r.choice(PARAM_NAMES).encode() if r.random() < 0.8 else \
            r.choice(ODD_PARAM_NAMES)
        read = M.MAVLink_param_request_read_message(ts, tc, name, -1)
        out = [read] if r.random() < 0.15 else []
        ptype = M.MAV_PARAM_TYPE_REAL32 if r.random() < 0.9 else self._int("uint8_t")
        out.append(M.MAVLink_param_set_message(ts, tc, name, self._param_value(name), ptype))
        k = r.random()
        if k < 0.6:
            out.append(read)
        elif k < 0.9:
            index = r.choice((-32768, -2, -1, 0, len(PARAM_NAMES) - 1, len(PARAM_NAMES),
                              32767, r.randint(-32768, 32767)))
            out.append(M.MAVLink_param_request_read_message(
                ts, tc, r.choice((b"", name, self.rng.randbytes(16))), index))
        else:
            out.append(M.MAVLink_param_request_list_message(ts, tc))
        return [self._pack(m, s) for m in out]

    def _setpoint(self) -> MAV.MAVLink_message:
        r = self.rng
        if r.random() < 0.4:
            msg = self.random_message("SET_POSITION_TARGET_LOCAL_NED")
            msg.target_system = 1
            return msg
        mask = r.choice((0, 0b110111111000, 0b110111000111, 0b100111111000, 0b010111111000,
                         r.getrandbits(16)))
        frame = M.MAV_FRAME_LOCAL_NED if r.random() < 0.9 else r.choice((0, 8, 9, 255))
        return M.MAVLink_set_position_target_local_ned_message(
            r.getrandbits(32), 1, 1, frame, mask, r.uniform(-5, 5), r.uniform(-5, 5),
            -r.uniform(1, 5), r.uniform(-1, 1), r.uniform(-1, 1), r.uniform(-1, 1),
            r.uniform(-1, 1), r.uniform(-1, 1), r.uniform(-1, 1), r.uniform(-math.pi, math.pi),
            0.0)

    def _attitude(self) -> MAV.MAVLink_message:
        r = self.rng
        half = r.uniform(-0.3, 0.3)
        q = r.choice(([1.0, 0.0, 0.0, 0.0], [0.0] * 4, [math.nan] * 4, [1e38] * 4, [0.5] * 4,
                      [math.cos(half), 0.0, 0.0, math.sin(half)],
                      [self._float() for _ in range(4)]))
        mask = r.choice((0, 7, 128, 255, r.getrandbits(8)))
        return M.MAVLink_set_attitude_target_message(
            r.getrandbits(32), 1, r.choice((1, 0)), mask, q,
            *(self._float() if r.random() < 0.3 else r.uniform(-0.5, 0.5) for _ in range(3)),
            r.choice((0.5, self._float())))

    def mode_arm(self) -> list[bytes]:
        s, r = self._sender(), self.rng
        variant = r.choices(("arm_cycle", "offboard", "set_mode", "land", "start"),
                            (3, 3, 2, 1, 2))[0]
        out: list[MAV.MAVLink_message] = []
        if variant == "arm_cycle":
            out.append(self._cmd(ARM, 1.0))
            out += [self._mode_command() for _ in range(r.randint(1, 4))]
            out.append(self._cmd(ARM, *r.choice(((0.0,), (0.0, 21196.0), (math.nan,), (2.0,),
                                                 (-1.0,), (1.0,), (0.0, math.nan),
                                                 (self._float(), self._float())))))
            if r.random() < 0.5:
                out.append(self._cmd(ARM, 1.0))
        elif variant == "offboard":
            out += [self._setpoint() for _ in range(r.randint(2, 8))]
            if r.random() < 0.5:
                out.append(self._cmd(ARM, 1.0))
            out.append(self._cmd(SET_MODE, 1.0, 6.0, 0.0))  # OFFBOARD
            for _ in range(r.randint(1, 6)):
                out.append(self._setpoint() if r.random() < 0.6 else self._attitude())
            if r.random() < 0.5:
                out.append(self._cmd(SET_MODE, 1.0, 4.0, 3.0))  # AUTO.LOITER (hold)
        elif variant == "set_mode":
            for _ in range(r.randint(1, 4)):
                custom = r.choice([m.custom_mode for m in Mode] + [
                    0, 0xFFFFFFFF, r.getrandbits(32), r.randint(0, 255) << 16,
                    (r.randint(0, 255) << 24) | (4 << 16)])
                out.append(M.MAVLink_set_mode_message(
                    r.choice((1, 1, 0, 2)), r.choice((1, 217, 0, 255, r.getrandbits(8))),
                    custom))
        elif variant == "land":
            out.append(self._cmd(ARM, 1.0))
            out.append(self._cmd(M.MAV_CMD_NAV_LAND, *(self._float() if r.random() < 0.3
                                                       else 0.0 for _ in range(7))))
            if r.random() < 0.3:
                out.append(self._cmd(ARM, 0.0, 21196.0))
        else:
            out.append(self._cmd(M.MAV_CMD_MISSION_START, r.choice(
                (0.0, 1.0, 3.0, -1.0, 0.5, math.nan, math.inf, 65535.0, 65536.0, F32_MAX)),
                self._float()))
            out.append(self._cmd(ARM, 1.0))
            out.append(self._cmd(SET_MODE, 1.0, 4.0, 4.0))
            out.append(self._cmd(M.MAV_CMD_DO_SET_MISSION_CURRENT, self._float()))
            r.shuffle(out)
        return [self._pack(m, s) for m in out]

    # -- single inputs

    def field_frame(self) -> bytes:
        kind = self.rng.choices(HANDLED, _FIELD_WEIGHTS)[0]
        return self._pack(self.random_message(kind), self._sender())

    def payload_frame(self) -> bytes:
        """A valid CRC around a payload of any length and content, for a handled id."""
        r = self.rng
        cls = _CLASSES[r.choice(HANDLED)]
        full = cls.unpacker.size
        n = r.choice((0, 1, max(full - 1, 0), full, full + 1, r.randint(0, 255)))
        pattern = r.choice((b"", b"\xff", b"\x00", b"\x00\x00\xc0\x7f", b"\x00\x00\x80\x7f",
                            b"\x00\x00\x80\xff", b"\xff\xff\x7f\x7f"))
        payload = r.randbytes(n) if not pattern else (pattern * (n // len(pattern) + 1))[:n]
        return self._frame(cls.id, payload, self._sender())

    def _some_frame(self) -> bytes:
        r = self.rng.random()
        if r < 0.5:
            return self.field_frame()
        if r < 0.75:
            return self.rng.choice(self.set_get())
        return self.rng.choice(self.param())

    def multi(self) -> bytes:
        """Several frames in one datagram, with bytes between and a tail cut short."""
        r = self.rng
        parts = []
        for _ in range(r.randint(2, 5)):
            parts.append(self._some_frame())
            if r.random() < 0.3:
                parts.append(r.randbytes(r.randint(1, 5)))
        if r.random() < 0.3:
            tail = self._some_frame()
            parts.append(tail[:r.randint(1, len(tail) - 1)])
        return b"".join(parts)

    def damaged(self) -> bytes:
        r = self.rng
        data = bytearray(self._some_frame())
        how = r.randrange(7)
        if how == 0:
            return bytes(data[:r.randint(1, len(data) - 1)])
        if how == 1:
            for bit in r.sample(range(8 * len(data)), r.randint(1, 3)):
                data[bit // 8] ^= 1 << (bit % 8)
        elif how == 2:
            data[1] = r.getrandbits(8)  # length
        elif how == 3:
            data[2] ^= r.choice((1, 2, 0x80))  # incompatibility flags (signed, unknown)
        elif how == 4:
            other = _CLASSES[r.choice(HANDLED)].id  # another message id: CRC extra differs
            data[7:10] = struct.pack("<I", other)[:3]
        elif how == 5:
            del data[r.randrange(len(data))]
        else:
            data += r.randbytes(r.randint(1, 40))
        return bytes(data)

    def next(self) -> Input:
        category = self.rng.choices(self._names, self._weights)[0]
        if category in SEQUENCE_KINDS:
            return Input(category, getattr(self, category)(), True)
        raw = self.raw
        if category == "field":
            frames = [self.field_frame()]
        elif category == "payload":
            frames = [self.payload_frame()]
        elif category == "multi":
            frames = [self.multi()]
        elif category == "damaged":
            frames = [self.damaged()]
        elif category == "random":
            frames = [raw.random_datagram()]
        elif category == "truncated":
            frames = [raw.truncated()]
        elif category == "bitflip":
            frames = [raw.bitflip()]
        elif category == "foreign":
            frames = [raw.foreign_frame()]
        else:
            frames = [raw.flood_frame() for _ in range(FLOOD_BURST)]
        return Input(category, frames, False)


# ----------------------------------------------------------------------------------------
# The listening link and the probes
# ----------------------------------------------------------------------------------------

SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)  # Linux; SCM_TIMESTAMPNS is the same


class LinkListener:
    """The FCU's second GCS link (`udpout` to our port): every datagram with its kernel
    arrival time (wall clock, seconds), whatever keeps this process busy. Nothing is sent."""

    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
        try:
            self.sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
        except OSError:
            pass
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.port = self.sock.getsockname()[1]
        self.created = time.time()
        self.parser = parser()
        self.heartbeats: list[float] = []
        self.states: list[tuple[float, bool, int]] = []  # (t, armed, custom_mode) changes
        self.per_second: Counter = Counter()  # int(t) -> datagrams
        self.streams_per_second: Counter = Counter()
        self.by_type: Counter = Counter()
        self.texts: list[tuple[float, str]] = []
        self.on_text: Callable[[float, str], None] | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="link2", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                readable, _, _ = select.select([self.sock], [], [], 0.2)
            except (OSError, ValueError):
                return
            if not readable:
                continue
            for _ in range(1000):
                try:
                    data, anc, _, _ = self.sock.recvmsg(65535, 64)
                except (BlockingIOError, InterruptedError):
                    break
                except OSError:
                    return
                t = time.time()
                for level, kind, raw in anc:
                    if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS and len(raw) >= 16:
                        sec, ns = struct.unpack("qq", raw[:16])
                        t = sec + ns * 1e-9
                self._datagram(data, t)

    def _datagram(self, data: bytes, t: float) -> None:
        sec = int(t)
        self.per_second[sec] += 1
        if len(data) < 10 or data[0] != 0xFD:
            self.by_type[None] += 1
            return
        msgid = data[7] | data[8] << 8 | data[9] << 16
        self.by_type[msgid] += 1
        if msgid in DEFAULT_INTERVALS_S:
            self.streams_per_second[sec] += 1
        if msgid not in (M.MAVLINK_MSG_ID_HEARTBEAT, M.MAVLINK_MSG_ID_STATUSTEXT):
            return
        try:
            msgs = self.parser.parse_buffer(data) or []
        except Exception:
            self.parser = parser()
            return
        for m in msgs:
            kind = m.get_type()
            if kind == "HEARTBEAT" and m.get_srcSystem() == 1 and \
                    m.get_srcComponent() == M.MAV_COMP_ID_AUTOPILOT1:
                self.heartbeats.append(t)
                state = (bool(m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED), m.custom_mode)
                if not self.states or self.states[-1][1:] != state:
                    self.states.append((t, *state))
            elif kind == "STATUSTEXT":
                self.texts.append((t, m.text))
                if self.on_text is not None:
                    self.on_text(t, m.text)

    def heartbeats_between(self, t0: float, t1: float) -> int:
        return sum(1 for h in self.heartbeats if t0 <= h <= t1)

    def summary(self, t1: float) -> dict:
        """The longest HEARTBEAT gap from the first heartbeat to `t1` (wall clock) and the
        messages per second received."""
        beats = self.heartbeats
        t0 = beats[0] if beats else self.created
        points = [t0, *(b for b in beats if t0 <= b <= t1), t1]
        gaps = [(b - a, a) for a, b in itertools.pairwise(points)]
        gap, gap_at = max(gaps)
        seconds = range(int(t0) + 1, int(t1))  # whole seconds only
        span = max(t1 - t0, 1e-9)
        total = sum(n for s, n in self.per_second.items() if t0 <= s + 0.5 <= t1)
        streams = sum(n for s, n in self.streams_per_second.items() if t0 <= s + 0.5 <= t1)
        names = {}
        for msgid, n in self.by_type.most_common(6):
            cls = M.mavlink_map.get(msgid) if msgid is not None else None
            names[cls.msgname if cls else "not MAVLink 2"] = round(n / span, 1)
        arms = sum(1 for a, b in itertools.pairwise(self.states) if a[1] != b[1])
        modes = sorted({m.name for _, _, c in self.states for m in Mode if m.custom_mode == c})
        return {"seconds": span, "heartbeats": len(beats), "gap_max_s": gap,
                "gap_at_s": gap_at - t0, "msg_s": total / span,
                "msg_s_max": max((self.per_second[s] for s in seconds), default=0),
                "stream_msg_s": streams / span,
                "stream_msg_s_max": max((self.streams_per_second[s] for s in seconds),
                                        default=0),
                "top_msg_s": names, "arm_changes": arms, "modes": modes,
                "internal_error_texts": sum(1 for _, x in self.texts if "internal error" in x)}

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self.sock.close()


class Prober:
    """Synchronous checks on link 1 from a socket of its own (module docstring). Each probe
    first syncs: a REQUEST_MESSAGE whose ACK comes once the FCU has read all that was sent
    before it, so that what follows answers the probe alone."""

    ROTATION = ("set_get", "param", "set_get", "streams", "set_get", "param", "set_get",
                "param", "set_get", "streams", "set_get", "param", "set_get", "param",
                "set_get", "heartbeat_off")

    def __init__(self, port: int, listener: LinkListener, signing_key: bytes | None,
                 seed: int) -> None:
        self.addr = ("127.0.0.1", port)
        self.listener = listener
        self.key = signing_key
        self.rng = random.Random(seed * 7919 + 1)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.link_id = PROBE_LINK_ID
        self.mav = self._encoder()
        self.parser = parser()
        self.outcomes: dict[str, Counter] = {}
        self.failures: list[str] = []
        self.stream_rates: list[float] = []  # link 1's streams, msg/s, all asked at 1 kHz
        self._turn = 0

    def _encoder(self, key: bytes | None = None, timestamp: int | None = None
                 ) -> MAV.MAVLink:
        mav = encoder(PROBE_SYSID, M.MAV_COMP_ID_MISSIONPLANNER)
        key = key or self.key
        if key is not None:
            mav.signing.secret_key = key
            mav.signing.sign_outgoing = True
            mav.signing.link_id = self.link_id
            mav.signing.timestamp = timestamp or signing_timestamp()
        return mav

    # -- link

    def send(self, msg: MAV.MAVLink_message, mav: MAV.MAVLink | None = None) -> bytes:
        data = pack(mav or self.mav, msg)
        self.send_bytes(data)
        return data

    def send_bytes(self, data: bytes) -> None:
        try:
            self.sock.sendto(data, self.addr)
        except OSError:
            pass

    def command(self, command: int, *params: float) -> bytes:
        p = [*params, *(0.0,) * (7 - len(params))]
        return self.send(M.MAVLink_command_long_message(1, 1, command, 0, *p))

    def drain(self) -> None:
        while True:
            try:
                self.sock.recv(65535)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                return

    def _datagrams(self, timeout: float):
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                return
            readable, _, _ = select.select([self.sock], [], [], left)
            if not readable:
                return
            while True:
                try:
                    yield self.sock.recv(65535)
                except (BlockingIOError, InterruptedError):
                    break
                except OSError:
                    return

    def recv(self, match: Callable, timeout: float = 2.0):
        for data in self._datagrams(timeout):
            try:
                msgs = self.parser.parse_buffer(data) or []
            except Exception:
                self.parser = parser()
                continue
            for m in msgs:
                if m.get_type() != "BAD_DATA" and m.get_srcSystem() == 1 and match(m):
                    return m
        return None

    def ack(self, command: int, timeout: float = 2.0) -> int | None:
        m = self.recv(lambda m: m.get_type() == "COMMAND_ACK" and m.command == command
                      and m.target_system == PROBE_SYSID, timeout)
        return None if m is None else m.result

    def sync(self) -> bool:
        for _ in range(3):
            self.drain()
            self.command(REQUEST, float(M.MAVLINK_MSG_ID_AUTOPILOT_VERSION))
            if self.ack(REQUEST, 3.0) is not None:
                return True
        return False

    # -- probes

    def _outcome(self, kind: str, ok: bool | None, text: str) -> None:
        result = "ok" if ok else "no answer" if ok is None else "FAILED"
        self.outcomes.setdefault(kind, Counter())[result] += 1
        if not ok and len(self.failures) < 30:
            self.failures.append(f"{kind}: {result}: {text}")

    def run(self, kind: str | None = None) -> None:
        if kind is None:
            kind = self.ROTATION[self._turn % len(self.ROTATION)]
            self._turn += 1
        if not self.sync():
            self._outcome(kind, None, "no answer to the sync (REQUEST_MESSAGE)")
            return
        getattr(self, f"probe_{kind}")()

    def get_interval(self, msg_id: int) -> tuple[int | None, int | None]:
        self.command(GET_IV, float(msg_id))
        result = self.ack(GET_IV)
        if result != M.MAV_RESULT_ACCEPTED:
            return result, None
        m = self.recv(lambda m: m.get_type() == "MESSAGE_INTERVAL" and m.message_id == msg_id)
        return result, None if m is None else m.interval_us

    def probe_set_get(self) -> None:
        r = self.rng
        msg_id = r.choice(STREAM_IDS) if r.random() < 0.85 else \
            r.choice((M.MAVLINK_MSG_ID_AUTOPILOT_VERSION, M.MAVLINK_MSG_ID_STATUSTEXT, 65535))
        iv = r.choice(INTERVALS_US) if r.random() < 0.7 else \
            float(r.randint(-2, 2**31 + 10)) if r.random() < 0.5 else r.uniform(1.0, 5e6)
        wire = f32(iv)
        _, g0 = self.get_interval(msg_id)
        self.command(SET_IV, float(msg_id), iv)
        result = self.ack(SET_IV)
        _, g1 = self.get_interval(msg_id)
        what = f"SET_MESSAGE_INTERVAL({msg_id}, {wire!r} us) then GET: ack {result}, " \
               f"interval {g0} -> {g1}"
        if None in (g0, result, g1):
            return self._outcome("set_get", None, what)
        valid = math.isfinite(wire) and (wire == -1.0 or 0.0 <= wire <= MAX_INTERVAL_US)
        if msg_id not in DEFAULT_INTERVALS_S or not valid:
            ok, expect = result == M.MAV_RESULT_DENIED and g1 == g0, f"DENIED and {g0}"
        elif result == M.MAV_RESULT_ACCEPTED:
            want = -1 if wire < 0 else round(DEFAULT_INTERVALS_S[msg_id] * 1e6) \
                if wire == 0 else max(round(wire), round(MIN_INTERVAL_S * 1e6))
            ok, expect = g1 == want, f"{want}"
        else:  # refused within the range: the link's budget; nothing may change
            ok, expect = result == M.MAV_RESULT_DENIED and g1 == g0, f"{g0} (budget)"
        self._outcome("set_get", ok, f"{what}, expected {expect}")

    def read_param(self, name: str):
        self.send(M.MAVLink_param_request_read_message(1, 1, name.encode(), -1))
        return self.recv(lambda m: m.get_type() == "PARAM_VALUE" and m.param_id == name)

    def probe_param(self) -> None:
        r = self.rng
        index = r.randrange(len(PARAM_SPECS))
        spec = PARAM_SPECS[index]
        value = r.choice((spec.lo, spec.hi, f32_step(spec.lo, up=False),
                          f32_step(spec.hi, up=True), (spec.lo + spec.hi) / 2,
                          r.uniform(spec.lo, spec.hi), math.nan, math.inf, -math.inf, 0.0,
                          -0.0, F32_MAX, 1e-45, spec.hi + 1.0, 0.5))
        wire = f32(value)
        m0 = self.read_param(spec.name)
        self.send(M.MAVLink_param_set_message(1, 1, spec.name.encode(), value,
                                              M.MAV_PARAM_TYPE_REAL32))
        m1 = self.recv(lambda m: m.get_type() == "PARAM_VALUE" and m.param_id == spec.name)
        m2 = self.read_param(spec.name)
        values = [None if m is None else m.param_value for m in (m0, m1, m2)]
        what = f"PARAM_SET({spec.name}, {wire!r}) then PARAM_REQUEST_READ: {values[0]!r} " \
               f"-> {values[1]!r}, read {values[2]!r} (range [{spec.lo:g}, {spec.hi:g}])"
        if m0 is None or m1 is None or m2 is None:
            return self._outcome("param", None, what)
        v0, v1, v2 = (float(m.param_value) for m in (m0, m1, m2))
        requested_ok = math.isfinite(wire) and spec.lo <= wire <= spec.hi and \
            (spec.unit != "enum" or wire == round(wire))
        ok = v1 == v2 and math.isfinite(v2) and spec.lo <= v2 <= spec.hi and \
            m2.param_count == len(PARAM_SPECS) and m2.param_index == index
        ok = ok and (v2 == v0 if not requested_ok else v2 in (wire, v0))
        self._outcome("param", ok, what)

    def _count(self, seconds: float) -> Counter:
        counts: Counter = Counter()
        for data in self._datagrams(seconds):
            if len(data) >= 10 and data[0] == 0xFD and data[5] == 1:
                counts[data[7] | data[8] << 8 | data[9] << 16] += 1
        return counts

    def probe_streams(self) -> None:
        """Every requestable id answered (ACCEPTED) and no other; then every stream of link
        1 off, some asked at 1 kHz (the first fills the budget), and what streams read for a
        second: within the link's budget; then every stream back to its default."""
        bad, missing = [], 0
        for msg_id in (*REQUESTABLE_IDS, *NOT_ANSWERED_IDS):
            self.command(REQUEST, float(msg_id))
            result = self.ack(REQUEST)
            want = M.MAV_RESULT_ACCEPTED if msg_id in REQUESTABLE else M.MAV_RESULT_UNSUPPORTED
            if result is None:
                missing += 1
            elif result != want:
                bad.append(f"REQUEST_MESSAGE({msg_id}): {result}, expected {want}")
        for msg_id in STREAM_IDS:  # turning a stream off is always possible
            self.command(SET_IV, float(msg_id), -1.0)
            result = self.ack(SET_IV)
            if result is None:
                missing += 1
            elif result != M.MAV_RESULT_ACCEPTED:
                bad.append(f"SET_MESSAGE_INTERVAL({msg_id}, -1): {result}, expected 0")
        fast = self.rng.sample(STREAM_IDS, self.rng.randint(3, len(STREAM_IDS)))
        accepted = []
        for msg_id in fast:
            self.command(SET_IV, float(msg_id), 1.0)  # 1 us: 1 kHz, if the budget allows
            if self.ack(SET_IV) == M.MAV_RESULT_ACCEPTED:
                accepted.append(msg_id)
        self.drain()
        counts = self._count(1.0)
        streams = {i: n for i, n in counts.items() if i in DEFAULT_INTERVALS_S}
        total = sum(streams.values())
        self.stream_rates.append(total)
        if total > LINK_BUDGET_MSG_S * 1.15 + 20:
            bad.append(f"{total} stream messages in 1 s > budget {LINK_BUDGET_MSG_S:.0f}")
        for i, n in streams.items():
            if n > 1000 * 1.15 + 5:
                bad.append(f"message {i}: {n} in 1 s > 1 kHz")
        for msg_id in (*accepted, *STREAM_IDS):  # the fast ones off, then all to default
            self.command(SET_IV, float(msg_id), -1.0 if msg_id in accepted else 0.0)
            accepted = [i for i in accepted if i != msg_id]
            result = self.ack(SET_IV)
            if result is not None and result != M.MAV_RESULT_ACCEPTED:
                bad.append(f"SET_MESSAGE_INTERVAL({msg_id}) back to its default: {result}")
        ok = False if bad else None if missing else True
        self._outcome("streams", ok, "; ".join(bad[:4]) + f" ({missing} commands unanswered; "
                      f"asked at 1 us: {fast}, {total} stream msg/s)")

    def probe_heartbeat_off(self) -> None:
        """HEARTBEAT off on link 1: none there for 2.5 s while link 2 keeps its own; then
        back to the default."""
        self.command(SET_IV, float(M.MAVLINK_MSG_ID_HEARTBEAT), -1.0)
        t0 = time.time()
        result = self.ack(SET_IV)
        if result != M.MAV_RESULT_ACCEPTED:
            return self._outcome("heartbeat_off", None if result is None else False,
                                 f"SET_MESSAGE_INTERVAL(HEARTBEAT, -1): ack {result}")
        heard = self.recv(lambda m: m.get_type() == "HEARTBEAT", 2.5)
        t1 = time.time()
        link2 = self.listener.heartbeats_between(t0, t1)
        self.command(SET_IV, float(M.MAVLINK_MSG_ID_HEARTBEAT), 0.0)
        back_result = self.ack(SET_IV)
        back = back_result == M.MAV_RESULT_DENIED or \
            self.recv(lambda m: m.get_type() == "HEARTBEAT", 2.5) is not None
        ok = heard is None and link2 >= 2 and back
        self._outcome("heartbeat_off", ok,
                      f"link 1 heard a heartbeat after turning it off: {heard is not None}; "
                      f"link 2 heartbeats in those {t1 - t0:.1f} s: {link2}; link 1's back "
                      f"after the default: {back} (ack {back_result})")

    def probe_signing(self) -> None:
        """A replayed frame is refused; a frame with a wrong signature and a timestamp
        1000 s ahead, on our stream, must not lock that stream out."""
        if self.key is None:
            return
        self.link_id += 1  # a fresh stream (link id, PROBE_SYSID, MISSIONPLANNER)
        self.mav = self._encoder()
        first = self.command(REQUEST, float(M.MAVLINK_MSG_ID_AUTOPILOT_VERSION))
        before = self.ack(REQUEST)
        self.send_bytes(first)  # the same frame again
        replayed = self.ack(REQUEST, 1.0)
        forger = self._encoder(key=secrets.token_bytes(32),
                               timestamp=self.mav.signing.timestamp + 100_000_000)
        self.send(M.MAVLink_command_long_message(1, 1, REQUEST, 0, 148.0, *(0.0,) * 6), forger)
        time.sleep(0.05)
        self.command(REQUEST, float(M.MAVLINK_MSG_ID_AUTOPILOT_VERSION))
        after = self.ack(REQUEST)
        self._outcome("signing_replay", replayed is None if before is not None else None,
                      f"a replayed signed frame was answered (ack {replayed})")
        self._outcome("signing_forged_timestamp", after is not None if before is not None
                      else None,
                      f"one frame with a WRONG signature and a timestamp 1000 s ahead on the "
                      f"stream (link {self.link_id}, {PROBE_SYSID}, "
                      f"{M.MAV_COMP_ID_MISSIONPLANNER}) locked that stream out: the next "
                      f"validly signed command got no answer (before: ack {before})")
        self.link_id += 1  # go on with a stream of our own
        self.mav = self._encoder()

    def summary(self) -> str:
        parts = [f"{k} " + "/".join(f"{n} {o}" for o, n in sorted(c.items()))
                 for k, c in sorted(self.outcomes.items())]
        return ", ".join(parts) or "none"

    @property
    def failed(self) -> int:
        return sum(c["FAILED"] + c["no answer"] for c in self.outcomes.values())

    def close(self) -> None:
        self.sock.close()


class SequenceCampaign:
    """The GCS ports' second campaign: `GcsSequences` inputs on link 1 at `rate` per second,
    a probe every `probe_every` inputs, internal errors (STATUSTEXT on the listening link)
    recorded with the inputs sent before them."""

    RING = 400

    def __init__(self, flight: Flight, attack: Attack, seed: int, rate: float,
                 probe_every: int) -> None:
        self.flight = flight
        self.attack = attack
        self.rate = rate
        self.probe_every = max(1, probe_every)
        self.gen = GcsSequences(seed, flight.signing_key)
        self.prober = Prober(flight.gcs_port, flight.listener, flight.signing_key, seed)
        self.rng = random.Random(seed + 2)
        self.ring: deque = deque(maxlen=self.RING)
        self.errors: list[tuple[float, str, list]] = []  # the first ones, with inputs
        self.error_texts: Counter = Counter()  # every one seen
        self.counts: Counter = Counter()
        self.sequences: Counter = Counter()
        self.in_sequences = 0
        self.sent = 0
        self.not_sent = 0
        self.seconds = 0.0  # sending, probes between inputs excluded
        self.probe_seconds = 0.0
        flight.listener.on_text = self._on_text

    def _on_text(self, t: float, text: str) -> None:
        if "internal error" not in text:
            return
        self.error_texts[text] += 1
        if len(self.errors) < 20:
            self.errors.append((t, text, list(self.ring.copy())))

    def _probe(self, kind: str | None = None) -> None:
        t = time.monotonic()
        self.prober.run(kind)
        self.probe_seconds += time.monotonic() - t

    def run(self, n: int) -> None:
        t0 = time.monotonic()
        paced_from, paced_sent = t0, 0
        next_probe = self.probe_every // 2
        if self.flight.signing_key is not None:
            self._probe("signing")
        fcu = self.flight.procs["fcu"]
        while self.sent < n and fcu.poll() is None:
            if self.sent >= next_probe:
                t = time.monotonic()
                self._probe()
                next_probe += self.probe_every
                paced_from += time.monotonic() - t
            inp = self.gen.next()
            sock = self.rng.choice(self.attack.socks)
            for data in inp.frames[:n - self.sent]:
                try:
                    sock.sendto(data, ("127.0.0.1", self.flight.gcs_port))
                except (BlockingIOError, ConnectionRefusedError):
                    self.not_sent += 1
                self.ring.append((time.time(), inp.category, data))
                self.counts[inp.category] += 1
                self.sent += 1
                paced_sent += 1
                if inp.sequence:
                    self.in_sequences += 1
            if inp.sequence:
                self.sequences[inp.category] += 1
            ahead = paced_sent / self.rate - (time.monotonic() - paced_from)
            if ahead > 0.002:
                time.sleep(ahead)
        self.seconds = time.monotonic() - t0 - self.probe_seconds
        if fcu.poll() is None:  # one probe of each kind after the last input
            for kind in ("set_get", "param", "streams", "heartbeat_off"):
                self._probe(kind)
            if self.flight.signing_key is not None:
                self._probe("signing")

    def report_errors(self, out: Path, detailed: int = 3) -> list[str]:
        """The internal errors seen on the listening link, by text; the first `detailed`
        with the inputs sent just before them (the first 20 with the last RING inputs in
        files beside the flight's logs)."""
        if not self.error_texts:
            return []
        lines = [f"{sum(self.error_texts.values())} STATUSTEXT 'internal error' on the "
                 f"listening link: " + _fmt(dict(self.error_texts.most_common()))]
        for k, (t, text, ring) in enumerate(self.errors):
            path = out / f"internal_error_{k}.txt"
            with path.open("w") as fh:
                fh.write(f"{text}\n")
                for ts, category, data in ring:
                    fh.write(f"{ts - t:+.4f} s {category}: {data.hex()} {describe(data)}\n")
            if k >= detailed:
                continue
            recent = [(ts, c, d) for ts, c, d in ring if t - 2.0 <= ts <= t][-8:]
            lines.append(f"#{k} '{text}' ({path}); last inputs before it:")
            lines += [f"      {ts - t:+.3f} s {c}: {describe(d)[:300]}" for ts, c, d in recent]
        return lines

    def close(self) -> None:
        self.prober.close()


# ----------------------------------------------------------------------------------------
# A real-time flight to attack
# ----------------------------------------------------------------------------------------


def _stop_with_parent() -> None:
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


@dataclass
class Telemetry:
    """What the ground station hears, for windows of the flight."""

    err_pos: list[tuple[float, float]] = field(default_factory=list)  # (wall time, m)
    heartbeats: list[float] = field(default_factory=list)
    errors_comm: list[tuple[float, int]] = field(default_factory=list)
    armed: list[tuple[float, bool]] = field(default_factory=list)
    texts: list[tuple[float, str]] = field(default_factory=list)
    mission: list[tuple[float, int, int]] = field(default_factory=list)  # (t, total, state)

    def window(self, t0: float, t1: float) -> dict:
        errs = [e for t, e in self.err_pos if t0 <= t <= t1]
        beats = [t0, *(t for t in self.heartbeats if t0 <= t <= t1), t1]
        comm = [c for t, c in self.errors_comm if t0 <= t <= t1]
        return {"err_pos_max_m": max(errs, default=math.nan), "err_pos_samples": len(errs),
                "heartbeat_gap_max_s": max(b - a for a, b in itertools.pairwise(beats)),
                "errors_comm": (comm[0], comm[-1]) if comm else None,
                "disarmed": any(not a for t, a in self.armed if t0 <= t <= t1),
                "mission_totals": sorted({n for t, n, _ in self.mission if t0 <= t <= t1}),
                "mission_active": all(s == M.MISSION_STATE_ACTIVE
                                      for t, _, s in self.mission if t0 <= t <= t1),
                "texts": [x for t, x in self.texts if t0 <= t <= t1]}


class Flight:
    """sitl + fcu in real time, the simulator link through a relay (`self.relay`), the
    FCU's first GCS link `udpin` on `self.gcs_port` with a ground-station session on it and
    a thread that records its telemetry once the mission has started, and its second GCS
    link `udpout` to `self.listener` (a `LinkListener`: nothing is ever sent on it)."""

    def __init__(self, out: Path, scenario: Path = SCENARIO, *, signing: bool = False) -> None:
        self.out = out
        out.mkdir(parents=True, exist_ok=True)
        self.signing_key = secrets.token_bytes(32) if signing else None
        self.scenario = load_scenario(scenario)
        self.sitl_port, self.gcs_port = free_port(), free_port()
        self.relay = UdpProxy(self.sitl_port, Impairment(), seed=0)
        self.listener = LinkListener()
        self.procs: dict[str, subprocess.Popen] = {}
        self.session: Session | None = None
        self.telemetry = Telemetry()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.stats: dict = {}
        try:
            self._start(scenario)
        except BaseException:
            self.stop()
            raise

    def _spawn(self, name: str, argv: list[str]) -> None:
        log = (self.out / f"{name}.log").open("wb")
        self.procs[name] = subprocess.Popen([sys.executable, "-m", *argv], cwd=ROOT,
                                            stdout=log, stderr=subprocess.STDOUT,
                                            stdin=subprocess.DEVNULL,
                                            preexec_fn=_stop_with_parent)
        log.close()

    def _start(self, scenario: Path) -> None:
        self._spawn("sitl", ["sitl.node", str(scenario), "--link",
                             f"udpin:127.0.0.1:{self.sitl_port}", "--realtime"])
        signing = []
        if self.signing_key is not None:  # MAVLink 2 signing on the GCS link
            key = self.out / "signing.key"
            key.write_text(self.signing_key.hex() + "\n")
            signing = ["--signing-key", str(key)]
        self._spawn("fcu", ["fcu.node", "--vehicle", str(VEHICLE), "--gains", str(PID),
                            "--sim", f"udpout:127.0.0.1:{self.relay.port}",
                            "--gcs", f"udpin:127.0.0.1:{self.gcs_port}",
                            "--gcs", f"udpout:127.0.0.1:{self.listener.port}",
                            "--realtime", "--stats", str(self.out / "fcu_stats.json"),
                            *signing])
        self.session = Session(f"udpout:127.0.0.1:{self.gcs_port}",
                               signing_key=self.signing_key)
        self.session.wait_vehicle(timeout=30.0)
        if self.session.recv(["ATTITUDE_QUATERNION"], timeout=15.0) is None:
            raise RuntimeError("the vehicle reports no state:\n" + self.log("fcu")[-2000:])
        self.fcu_sim_port = int(re.search(r"fcu: sim port (\d+)", self.log("fcu")).group(1))

    def log(self, name: str) -> str:
        return (self.out / f"{name}.log").read_text(errors="replace")

    def start_mission(self) -> None:
        """Upload the scenario's mission, arm, MISSION_START (as `gcs run` does)."""
        s = self.session
        items = scenario_mission(self.scenario)
        self.mission_items = len(items)
        result = upload(s.conn, s.target_system, s.target_component, items, send=s.send)
        if result != M.MAV_MISSION_ACCEPTED:
            raise RuntimeError(f"mission upload refused: {result}")
        for command, params in ((M.MAV_CMD_COMPONENT_ARM_DISARM, (1.0,)),
                                (M.MAV_CMD_MISSION_START, (0.0, float(len(items) - 1)))):
            ack = s.command(command, *params)
            if ack != M.MAV_RESULT_ACCEPTED:
                raise RuntimeError(f"command {command} refused: {ack}")
        self._thread = threading.Thread(target=self._listen, name="telemetry", daemon=True)
        self._thread.start()

    def _listen(self) -> None:
        tm = self.telemetry
        while not self._stop.is_set():
            msg = self.session.recv(["HEARTBEAT", "NAMED_VALUE_FLOAT", "SYS_STATUS",
                                     "STATUSTEXT", "MISSION_CURRENT"], timeout=0.2)
            if msg is None or msg.get_srcSystem() != 1:
                continue
            now = time.monotonic()
            kind = msg.get_type()
            if kind == "HEARTBEAT" and msg.get_srcComponent() == M.MAV_COMP_ID_AUTOPILOT1:
                tm.heartbeats.append(now)
                tm.armed.append((now, bool(msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)))
            elif kind == "NAMED_VALUE_FLOAT" and msg.name == "ERR_POS":
                tm.err_pos.append((now, msg.value))
            elif kind == "SYS_STATUS":
                tm.errors_comm.append((now, msg.errors_comm))
            elif kind == "STATUSTEXT":
                tm.texts.append((now, msg.text))
            elif kind == "MISSION_CURRENT":
                tm.mission.append((now, msg.total, msg.mission_state))

    def pause_telemetry(self) -> None:
        """Stop recording link 1's telemetry (the session goes on sending heartbeats)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)

    def crashed(self) -> dict[str, int]:
        return {name: p.returncode for name, p in self.procs.items() if p.poll() is not None}

    def stop(self) -> dict:
        """Stop everything; the FCU's statistics and the simulator's counters."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        if self.session is not None:
            self.session.close()
        codes = {}
        for p in self.procs.values():
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
        for name, p in self.procs.items():
            try:
                codes[name] = p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
                codes[name] = p.wait()
        self.relay.close()
        self.listener.close()
        stats_path = self.out / "fcu_stats.json"
        fcu = json.loads(stats_path.read_text()) if stats_path.exists() else {}
        sitl = {}
        m = re.search(r"(\d+) re-sends, (\d+) answers ignored, (\d+) bytes rejected",
                      self.log("sitl")) if "sitl" in self.procs else None
        if m:
            sitl = {"resends": int(m.group(1)), "ignored_answers": int(m.group(2)),
                    "rejected_bytes": int(m.group(3))}
        self.stats = {"fcu": fcu, "sitl": sitl, "exit_codes": codes}
        return self.stats


class Attack:
    """Sockets and send functions for hitting one port of a Flight."""

    def __init__(self, flight: Flight, port: str, sockets: int = 4) -> None:
        self.flight = flight
        self.port = port
        self.socks = []
        for _ in range(sockets):
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            s.bind(("127.0.0.1", 0))
            s.setblocking(False)
            self.socks.append(s)
        self.rng = random.Random(port)
        self.dropped_by_sender = 0
        self.direct = Counter()  # sim: inputs sent straight to the FCU's sim port

    def _sendto(self, data: bytes, port: int) -> None:
        try:
            self.rng.choice(self.socks).sendto(data, ("127.0.0.1", port))
        except (BlockingIOError, ConnectionRefusedError):
            self.dropped_by_sender += 1

    def send(self, data: bytes, category: str) -> None:
        f = self.flight
        if self.port == "gcs":
            self._sendto(data, f.gcs_port)
        elif self.port == "sitl":
            self._sendto(data, f.sitl_port)
        elif self.rng.random() < 0.1:
            # straight to the FCU's simulator port from another socket: the link reads only
            # its simulator's replies, so none of these reaches the FCU
            self._sendto(data, f.fcu_sim_port)
            self.direct[category] += 1
        elif not f.relay.inject(data):
            self.dropped_by_sender += 1

    def close(self) -> None:
        for s in self.socks:
            s.close()


# ----------------------------------------------------------------------------------------
# The campaign
# ----------------------------------------------------------------------------------------


def _fmt(d: dict) -> str:
    return ", ".join(f"{k} {v}" for k, v in d.items())


def run_port(port: str | None, out: Path, inputs: int, rate: float, seed: int,
             settle_s: float = 4.0, baseline_s: float = 20.0, *, seq_rate: float = 2500.0,
             probe_every: int = 2000) -> dict:
    """One flight attacked on `port` (None: a baseline flight of `baseline_s`); "gcs-signed"
    attacks the GCS link of an FCU that requires MAVLink 2 signing. On the GCS ports the
    non-destructive attack is followed by the sequence campaign, in the same flight."""
    signed = port == "gcs-signed"
    target = "gcs" if signed else port
    flight = Flight(out, signing=signed)
    counts: Counter = Counter()
    attack = None
    campaign = None
    try:
        flight.start_mission()
        time.sleep(settle_s)
        t0 = time.monotonic()
        if target is None:
            time.sleep(baseline_s)
        else:
            attack = Attack(flight, target)
            blast(Traffic(target, seed), attack.send, inputs, rate, counts)
            time.sleep(1.0)  # let the last inputs be read
        t1 = time.monotonic()
        time.sleep(2.0)  # and the flight go on after the attack
        after = flight.telemetry.window(t1, time.monotonic())
        during = flight.telemetry.window(t0, t1)
        crashed = flight.crashed()
        if target == "gcs" and inputs > 0 and not crashed:
            flight.pause_telemetry()  # link 1 is about to be reconfigured at will
            assert attack is not None
            campaign = SequenceCampaign(flight, attack, seed, seq_rate, probe_every)
            campaign.run(inputs)
            time.sleep(2.0)  # the answers and streams after the last input
        fcu_alive = flight.procs["fcu"].poll() is None
        listen = flight.listener.summary(time.time())
        crashed_end = flight.crashed()
    finally:
        if attack is not None:
            attack.close()
        if campaign is not None:
            campaign.close()
        stats = flight.stop()
    seq = None
    if campaign is not None:
        pr = campaign.prober
        seq = {"inputs": campaign.sent, "in_sequences": campaign.in_sequences,
               "sequences": campaign.sequences, "by_category": campaign.counts,
               "seconds": campaign.seconds, "probe_seconds": campaign.probe_seconds,
               "not_sent": campaign.not_sent, "probes": pr.summary(),
               "probe_failures": pr.failures, "probes_failed": pr.failed,
               "link1_stream_msg_s_max": max(pr.stream_rates, default=None),
               "internal_errors": campaign.report_errors(out)}
    internal = stats["fcu"].get("internal_errors")
    log_tail = flight.log("fcu")[-4000:] if not fcu_alive or internal else ""
    return {"port": port or "baseline", "inputs": sum(counts.values()), "by_category": counts,
            "mission_items": flight.mission_items,
            "direct_to_fcu_sim_port": sum(attack.direct.values()) if attack else 0,
            "not_sent_buffer_full": attack.dropped_by_sender if attack else 0,
            "seconds": t1 - t0, "crashed": crashed, "crashed_end": crashed_end,
            "during": during, "after": after, "stats": stats, "fcu_alive": fcu_alive,
            "listen": listen, "sequences": seq, "fcu_log_tail": log_tail}


def run_spoof(kind: str, out: Path, seconds: float = 2.0) -> dict:
    """Valid frames from another system id that the target should ignore: simulator states
    to the FCU (through the relay) or actuator commands to the simulator."""
    flight = Flight(out)
    sent = 0
    try:
        flight.start_mission()
        time.sleep(4.0)
        t0 = time.monotonic()
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("127.0.0.1", 0))
        seq = 0
        while time.monotonic() - t0 < seconds:
            seq = (seq + 1) & 0xFF
            if kind == "states":
                odo = Odometry(int(time.monotonic() * 1e6), (3.0, 3.0, -3.0),
                               (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
                flight.relay.inject(pack_odometry(odo, seq, 42, M.MAV_COMP_ID_PERIPHERAL))
            else:
                a = ActuatorControls(0, (0.0,) * 16, 0, 1)  # disarmed: rotors stopped
                sock.sendto(pack_actuator_controls(a, seq, 42, M.MAV_COMP_ID_AUTOPILOT1),
                            ("127.0.0.1", flight.sitl_port))
            sent += 1
            time.sleep(0.002)
        sock.close()
        t1 = time.monotonic()
        time.sleep(2.0)
        during = flight.telemetry.window(t0, time.monotonic())
        crashed = flight.crashed()
    finally:
        stats = flight.stop()
    return {"attack": kind, "sent": sent, "seconds": t1 - t0, "crashed": crashed,
            "during_and_after": during, "stats": stats}


def report_port(r: dict) -> bool:
    """The flight's report; True when it kept its mission under the non-destructive
    attack (the sequence campaign that follows on the GCS ports changes it at will)."""
    d, a, st = r["during"], r["after"], r["stats"]
    fcu, sitl = st["fcu"], st["sitl"]
    mission_kept = d["mission_totals"] == a["mission_totals"] == [r["mission_items"]] and \
        d["mission_active"] and a["mission_active"]
    ok = not r["crashed"] and d["err_pos_max_m"] < ERR_POS_LIMIT_M and \
        a["err_pos_max_m"] < ERR_POS_LIMIT_M and not d["disarmed"] and \
        a["heartbeat_gap_max_s"] < 2.0 and mission_kept
    print(f"== {r['port']}: {r['inputs']} inputs in {r['seconds']:.1f} s "
          f"({r['inputs'] / max(r['seconds'], 1e-9):.0f}/s)")
    if r["inputs"]:
        print(f"   by category: {_fmt(dict(sorted(r['by_category'].items())))}")
    if r["direct_to_fcu_sim_port"]:
        print(f"   of which {r['direct_to_fcu_sim_port']} straight to the FCU's sim port from "
              "other sockets (dropped by its link), the rest through the relay")
    if r["not_sent_buffer_full"]:
        print(f"   not sent (our socket buffer full): {r['not_sent_buffer_full']}")
    print(f"   crashed: {r['crashed_end'] or 'none'}; exit codes {st['exit_codes']}")
    print(f"   FCU: {fcu.get('steps')} steps, {fcu.get('deadline_misses')} deadline misses, "
          f"{fcu.get('rejected_bytes')} bytes rejected, {fcu.get('ignored_messages')} "
          f"messages ignored, {fcu.get('signing_rejects')} refused by signing, "
          f"{fcu.get('internal_errors')} internal errors")
    if sitl:
        print(f"   SITL: {sitl['rejected_bytes']} bytes rejected, "
              f"{sitl['ignored_answers']} answers ignored")
    print(f"   during: ERR_POS max {d['err_pos_max_m']:.4f} m ({d['err_pos_samples']} "
          f"samples), heartbeat gap max {d['heartbeat_gap_max_s']:.2f} s, SYS_STATUS "
          f"errors_comm {d['errors_comm']}, disarmed {d['disarmed']}")
    print(f"   after:  ERR_POS max {a['err_pos_max_m']:.4f} m, heartbeat gap max "
          f"{a['heartbeat_gap_max_s']:.2f} s")
    if d["texts"]:
        print(f"   STATUSTEXT: {sorted(set(d['texts']))[:6]}")
    print(f"   mission: {r['mission_items']} items uploaded; MISSION_CURRENT totals during "
          f"{d['mission_totals']}, after {a['mission_totals']}; active throughout "
          f"{d['mission_active'] and a['mission_active']}")
    print(f"   flight kept its mission: {'yes' if ok else 'NO'}")
    s = r["sequences"]
    if s is not None:
        print(f"   sequence campaign: {s['inputs']} inputs in {s['seconds']:.1f} s "
              f"({s['inputs'] / max(s['seconds'], 1e-9):.0f}/s; probes took "
              f"{s['probe_seconds']:.1f} s more), {s['in_sequences']} of them in "
              f"{sum(s['sequences'].values())} sequences "
              f"({_fmt(dict(sorted(s['sequences'].items())))})")
        print(f"   inputs by category: {_fmt(dict(sorted(s['by_category'].items())))}"
              + (f"; not sent (our socket buffer full): {s['not_sent']}" if s["not_sent"]
                 else ""))
        print(f"   probes: {s['probes']}; link 1 streams asked at 1 kHz: max "
              f"{s['link1_stream_msg_s_max']} msg/s (budget {LINK_BUDGET_MSG_S:.0f})")
        for line in s["probe_failures"][:12]:
            print(f"     {line}")
        for line in s["internal_errors"]:
            print(line if line.startswith("      ") else f"   internal errors: {line}")
    li = r["listen"]
    print(f"   listening link: {li['heartbeats']} heartbeats in {li['seconds']:.0f} s, longest "
          f"gap {li['gap_max_s']:.2f} s (at +{li['gap_at_s']:.0f} s); {li['msg_s']:.0f} msg/s "
          f"(max {li['msg_s_max']} in one second), streams {li['stream_msg_s']:.0f} msg/s "
          f"(max {li['stream_msg_s_max']}); top {_fmt(li['top_msg_s'])}")
    print(f"   live state seen there: {li['arm_changes']} arm/disarm changes, modes "
          f"{', '.join(li['modes']) or '-'}")
    if r["fcu_log_tail"]:
        print("   fcu log (end):")
        for line in r["fcu_log_tail"].splitlines()[-40:]:
            print(f"     | {line}")
    return ok


def report_spoof(r: dict) -> None:
    d, st = r["during_and_after"], r["stats"]
    what = {"states": "ODOMETRY from system 42 through the simulator link (3 m away)",
            "commands": "HIL_ACTUATOR_CONTROLS from system 42 to the simulator (rotors off)"}
    print(f"== spoof: {r['sent']} x {what[r['attack']]} in {r['seconds']:.1f} s")
    print(f"   crashed: {r['crashed'] or 'none'}; ERR_POS max {d['err_pos_max_m']:.3f} m, "
          f"disarmed {d['disarmed']}, STATUSTEXT {sorted(set(d['texts']))[:4]}")
    print(f"   FCU: {st['fcu'].get('deadline_misses')} deadline misses, "
          f"{st['fcu'].get('ignored_messages')} messages ignored; SITL: "
          f"{st['sitl'].get('ignored_answers')} answers ignored; ignored as it should: "
          f"{'yes' if d['err_pos_max_m'] < ERR_POS_LIMIT_M and not d['disarmed'] else 'NO'}")


def summarize(r: dict, mission_ok: bool, gap_limit: float) -> list[str]:
    """The port's summary; returns what failed (empty: passed)."""
    fcu, li, s = r["stats"]["fcu"], r["listen"], r["sequences"]
    code = r["stats"]["exit_codes"].get("fcu")
    total = r["inputs"] + (s["inputs"] if s else 0)
    failed = []
    if not r["fcu_alive"]:
        failed.append(f"the fcu died (exit code {code})")
    internal = fcu.get("internal_errors")
    if internal is None:
        failed.append("no FCU statistics")
    elif internal:
        failed.append(f"internal_errors {internal}")
    if li["gap_max_s"] >= gap_limit:
        failed.append(f"HEARTBEAT gap {li['gap_max_s']:.2f} s on the listening link")
    if s and s["probes_failed"]:
        failed.append(f"{s['probes_failed']} probes failed")
    if not mission_ok:
        failed.append("the flight left its mission under the non-destructive attack")
    print(f"== summary {r['port']}")
    if s:
        print(f"   inputs sent: {total} ({r['inputs']} non-destructive, {s['inputs']} in the "
              f"sequence campaign); sequences: {sum(s['sequences'].values())} holding "
              f"{s['in_sequences']} inputs ({100 * s['in_sequences'] / max(total, 1):.0f} %)")
    else:
        print(f"   inputs sent: {total}; sequences: 0")
    print(f"   fcu alive: {'yes' if r['fcu_alive'] else 'NO'} (exit code {code}"
          f"{' after SIGTERM' if r['fcu_alive'] else ''})")
    print(f"   FCU stats: internal_errors {internal}, ignored_messages "
          f"{fcu.get('ignored_messages')}, rejected_bytes {fcu.get('rejected_bytes')}")
    print(f"   listening link: longest HEARTBEAT gap {li['gap_max_s']:.2f} s (bound "
          f"{gap_limit:g} s), {li['msg_s']:.0f} msg/s received (max {li['msg_s_max']} in one "
          f"second; streams {li['stream_msg_s']:.0f} msg/s, max {li['stream_msg_s_max']})")
    print(f"   verdict: {'OK' if not failed else 'FAILED: ' + '; '.join(failed)}")
    return failed


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--inputs", type=int, default=100_000,
                   help="inputs per port (the GCS ports: that many again in sequences)")
    p.add_argument("--rate", type=float, default=5000.0,
                   help="non-destructive inputs per second (average)")
    p.add_argument("--seq-rate", type=float, default=2500.0,
                   help="sequence campaign inputs per second (average)")
    p.add_argument("--probe-every", type=int, default=2000,
                   help="a probe every this many sequence campaign inputs")
    p.add_argument("--gap-limit", type=float, default=GAP_LIMIT_S,
                   help="longest HEARTBEAT gap allowed on the listening link, s")
    p.add_argument("--ports", default=",".join(CAMPAIGN_PORTS),
                   help=f"comma-separated, some of {','.join(CAMPAIGN_PORTS)}")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--no-spoof", action="store_true", help="skip the spoofing findings")
    p.add_argument("--out", type=Path, help="keep the flights' logs here")
    args = p.parse_args(argv)
    ports = [x for x in args.ports.split(",") if x]
    if any(x not in CAMPAIGN_PORTS for x in ports):
        p.error(f"--ports: expected some of {','.join(CAMPAIGN_PORTS)}")
    if args.inputs < 0 or args.rate <= 0 or args.seq_rate <= 0:
        p.error("--inputs must be >= 0, --rate and --seq-rate > 0")
    tmp = None
    if args.out is None:
        tmp = tempfile.TemporaryDirectory(prefix="fuzz_campaign_")
        out = Path(tmp.name)
    else:
        out = args.out
    results: list[tuple[dict, bool]] = []
    try:
        base = run_port(None, out / "baseline", 0, args.rate, args.seed,
                        baseline_s=max(args.inputs / args.rate, 5.0))
        results.append((base, report_port(base)))
        for port in ports:  # the signed GCS link gets the very inputs of the unsigned one
            seed = args.seed + PORTS.index(port.removesuffix("-signed"))
            r = run_port(port, out / port, args.inputs, args.rate, seed,
                         seq_rate=args.seq_rate, probe_every=args.probe_every)
            results.append((r, report_port(r)))
        if not args.no_spoof:
            for kind in ("states", "commands"):
                report_spoof(run_spoof(kind, out / f"spoof_{kind}"))
        failed = [(r["port"], summarize(r, ok, args.gap_limit)) for r, ok in results]
    finally:
        if tmp is not None:
            tmp.cleanup()
    bad = [f"{port}: {'; '.join(why)}" for port, why in failed if why]
    print("campaign:", "every port passed (fcu alive, no internal error, listening link's "
          "heartbeat within the bound, probes agreed, mission kept)" if not bad else
          "FAILED: " + " | ".join(bad))
    return 0 if not bad else 1


if __name__ == "__main__":
    sys.exit(main())
