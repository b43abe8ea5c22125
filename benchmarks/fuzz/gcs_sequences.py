"""Sequences for the FCU's GCS link, where what one message sets the next one reads (the
entry's docstring lists them), and the single inputs mixed with them."""

from __future__ import annotations

import math
import struct
from typing import Any

from benchmarks.fuzz.gcs_messages import (
    ARM,
    F32_MAX,
    FIELD_WEIGHTS,
    GET_IV,
    INT32_EXTREMES,
    MESSAGE_CLASSES,
    NOT_ANSWERED_IDS,
    ODD_PARAM_NAMES,
    PARAM_NAMES,
    REQUEST,
    REQUESTABLE_IDS,
    SENDERS,
    SET_IV,
    SET_MODE,
    STREAM_IDS,
    GcsMessages,
    Input,
    f32_step,
)
from benchmarks.fuzz.traffic import FLOOD_BURST
from common.wire.mavlink import MAV
from common.wire.mission_items import local_xy
from common.wire.modes import Mode
from fcu.edge.gcs_server import HANDLED
from fcu.mission.codes import SUPPORTED_COMMANDS as MISSION_COMMANDS
from fcu.params import SPECS as PARAM_SPECS

M = MAV
SEQUENCE_KINDS = ("set_get", "request_stream", "mission", "param", "mode_arm")
# picks (not inputs): a sequence is several inputs, a flood FLOOD_BURST of them; about two
# thirds of the inputs end up in sequences
SEQUENCE_MIX = (("set_get", 10.0), ("request_stream", 0.5), ("mission", 3.0), ("param", 8.0),
                ("mode_arm", 4.0), ("field", 30.0), ("payload", 8.0), ("multi", 3.0),
                ("damaged", 6.0), ("random", 5.0), ("truncated", 3.0), ("bitflip", 3.0),
                ("foreign", 3.0), ("flood", 0.01))


class GcsSequences(GcsMessages):
    """Inputs for the FCU's GCS link that it reads and obeys: sequences and single messages
    with any field values (module docstring). Seeded; signed with `signing_key` when given
    (with a few unsigned, wrongly signed and replayed frames)."""

    def __init__(self, seed: int, signing_key: bytes | None = None) -> None:
        super().__init__(seed, signing_key)
        self._names = [c for c, _ in SEQUENCE_MIX]
        self._weights = [w for _, w in SEQUENCE_MIX]

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

    def _valid_item(self, seq: int) -> dict[str, Any]:
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
        kind = self.rng.choices(HANDLED, FIELD_WEIGHTS)[0]
        return self._pack(self.random_message(kind), self._sender())

    def payload_frame(self) -> bytes:
        """A valid CRC around a payload of any length and content, for a handled id."""
        r = self.rng
        cls = MESSAGE_CLASSES[r.choice(HANDLED)]
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
            other = MESSAGE_CLASSES[r.choice(HANDLED)].id  # another message id: CRC extra differs
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
