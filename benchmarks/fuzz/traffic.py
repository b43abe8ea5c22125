"""Non-destructive hostile datagrams (random, truncated, bit-flipped, foreign, floods) and
sending them at a rate."""

from __future__ import annotations

import math
import random
import threading
import time
from collections import Counter
from collections.abc import Callable

from benchmarks.fuzz.config import PORTS
from common.wire.mavlink import MAV, encoder, pack
from common.wire.simlink import ActuatorControls, Odometry, pack_actuator_controls, pack_odometry

M = MAV


MIX = (("random", 0.30), ("truncated", 0.20), ("bitflip", 0.25), ("foreign", 0.15),
       ("flood", 0.10))
FLOOD_BURST = 500


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
          counts: Counter[str], stop: threading.Event | None = None) -> None:
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
