"""Property-based fuzzing of everything that parses input from outside: the simulator link's
lean frame parser (`common.wire.simlink`), the vehicle side of the mission protocol
(`fcu.edge.mission_protocol.MissionServer`) and the mission files (`gcs.mission_files`).

Arbitrary input must never raise, never yield a frame whose CRC is wrong, account for every
byte it rejects, and never change the stored mission unless an upload (or a clear) is
answered with MAV_MISSION_ACCEPTED.
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

from hypothesis import HealthCheck, assume, event, given, settings
from hypothesis import strategies as st

from common.wire.mavlink import MAV, encoder, pack, parser
from common.wire.mission_items import MissionItem
from common.wire.simlink import (
    HIL_ACTUATOR_CONTROLS_ID,
    HIL_SENSOR_ID,
    ODOMETRY_ID,
    ActuatorControls,
    FrameReader,
    HilSensor,
    Odometry,
    pack_actuator_controls,
    pack_hil_sensor,
    pack_odometry,
    split_frames,
    unpack_actuator_controls,
    unpack_hil_sensor,
    unpack_odometry,
)
from fcu.edge.mission_protocol import MissionServer, item_from_message
from fcu.mission.limits import MissionLimits
from fcu.mission.validation import validate_mission
from gcs.mission_files import read_mission
from gcs.mission_files.items import MissionFileError
from gcs.mission_files.toml import parse_toml
from gcs.mission_files.wpl import parse_wpl

M = MAV
FAST = settings(max_examples=300, deadline=None,
                suppress_health_check=[HealthCheck.too_slow])

# ----------------------------------------------------------------------------------------
# The simulator link's frame parser
# ----------------------------------------------------------------------------------------

f32 = st.floats(width=32)  # NaN, infinities and subnormals included
vec3 = st.tuples(f32, f32, f32)
u8 = st.integers(0, 255)

odometry = st.builds(Odometry, st.integers(0, 2**64 - 1), vec3, st.tuples(f32, f32, f32, f32),
                     vec3, vec3, u8, st.lists(f32, min_size=21, max_size=21).map(tuple), u8,
                     u8)
hil_sensor = st.builds(HilSensor, st.integers(0, 2**64 - 1), vec3, vec3, vec3, f32, f32, f32,
                       st.integers(0, 2**32 - 1))
controls = st.builds(ActuatorControls, st.integers(0, 2**64 - 1),
                     st.lists(f32, min_size=16, max_size=16).map(tuple), u8,
                     st.integers(0, 2**64 - 1))


@st.composite
def hot_frame(draw) -> bytes:
    """A valid ODOMETRY (state or pose), HIL_SENSOR or HIL_ACTUATOR_CONTROLS frame with any
    field values and identity."""
    seq, sysid, compid = draw(u8), draw(u8), draw(u8)
    kind = draw(st.integers(0, 2))
    if kind == 0:
        return pack_odometry(draw(odometry), seq, sysid, compid)
    if kind == 1:
        return pack_hil_sensor(draw(hil_sensor), seq, sysid, compid)
    return pack_actuator_controls(draw(controls), seq, sysid, compid)


@st.composite
def other_frame(draw) -> bytes:
    """A valid frame of another message of the dialect (as on a shared link)."""
    mav = encoder(draw(st.integers(1, 255)), draw(u8))
    kind = draw(st.sampled_from(["heartbeat", "hil_state_quaternion", "command_long"]))
    if kind == "heartbeat":
        msg = M.MAVLink_heartbeat_message(draw(u8), draw(u8), draw(u8), 0, draw(u8), 3)
    elif kind == "hil_state_quaternion":
        i16 = st.integers(-2**15, 2**15 - 1)
        msg = M.MAVLink_hil_state_quaternion_message(
            draw(st.integers(0, 2**64 - 1)), [draw(f32) for _ in range(4)],
            *(draw(f32) for _ in range(3)), *(draw(st.integers(-2**31, 2**31 - 1))
                                              for _ in range(3)),
            *(draw(i16) for _ in range(3)), draw(st.integers(0, 2**16 - 1)),
            draw(st.integers(0, 2**16 - 1)), *(draw(i16) for _ in range(3)))
    else:
        msg = M.MAVLink_command_long_message(draw(u8), draw(u8), draw(st.integers(0, 65535)),
                                             draw(u8), *(draw(f32) for _ in range(7)))
    return pack(mav, msg)


valid_frame = st.one_of(hot_frame(), hot_frame(), other_frame())
# Junk that contains start markers and plausible headers, not just random bytes.
junk = st.one_of(
    st.binary(max_size=64),
    st.lists(st.sampled_from([b"\xfd", b"\xfd\xff", b"\xfd\x00\x00", b"\x00", b"\xfe",
                              b"\xfd\xe9\x00\x00\x01\x01\xc8\x4b\x01\x00",
                              b"\xfd\x51\x00\x00\x07\x01\xc8\x5d\x00\x00"]),
             max_size=8).map(b"".join),
)


def crc_ok(raw: bytes) -> bool:
    """The oracle: pymavlink decodes the frame (it checks the CRC with CRC_EXTRA)."""
    try:
        parser().decode(bytearray(raw))
    except Exception:
        return False
    return True


def check_split(data: bytes, frames, rejected: int, tail: bytes = b"") -> None:
    """Every returned frame is a valid MAVLink 2 frame lying in `data`, and every byte is in
    a frame, rejected, or (stream) in the tail."""
    assert rejected + sum(len(f.raw) for f in frames) + len(tail) == len(data)
    pos = 0
    for f in frames:
        at = data.find(f.raw, pos)
        assert at >= pos and crc_ok(f.raw), f
        assert (f.msg_id, f.sysid, f.compid) == (
            f.raw[7] | f.raw[8] << 8 | f.raw[9] << 16, f.raw[5], f.raw[6])
        if f.msg_id == ODOMETRY_ID:
            unpack_odometry(f.payload)
        elif f.msg_id == HIL_SENSOR_ID:
            unpack_hil_sensor(f.payload)
        elif f.msg_id == HIL_ACTUATOR_CONTROLS_ID:
            unpack_actuator_controls(f.payload)
        else:
            assert f.payload == b""
        pos = at + len(f.raw)
    assert data.endswith(tail)


def recovered(data: bytes, frames, frame: bytes, at: int) -> bool:
    """`frame` (at offset `at` of `data`) was returned, or an accepted frame covers its
    start (possible only if junk before it happened to hold a frame with a valid CRC)."""
    pos = 0
    for f in frames:
        start = data.find(f.raw, pos)
        if start == at and f.raw == frame:
            return True
        if start < at < start + len(f.raw):
            return True
        pos = start + len(f.raw)
    return False


@FAST
@given(st.binary(max_size=700), st.lists(st.integers(1, 200), max_size=8))
def test_arbitrary_bytes_never_raise_and_every_byte_is_accounted(data, cuts):
    frames, rejected = split_frames(data)
    check_split(data, frames, rejected)
    assert FrameReader(stream=False).feed(("127.0.0.1", 9), data) == (frames, rejected)
    frames, rejected, tail = split_frames(data, stream=True)
    check_split(data, frames, rejected, tail)
    assert len(tail) < 280  # at most one incomplete frame is carried
    # the same bytes as a stream cut anywhere: the same frames, every byte accounted
    reader, got, count, pos = FrameReader(stream=True), [], 0, 0
    for n in [*cuts, len(data)]:
        f, r = reader.feed("peer", data[pos:pos + n])
        got += f
        count += r
        pos += n
    check_split(data, got, count, reader.tails.get("peer", b""))


@FAST
@given(st.lists(st.tuples(junk, valid_frame), min_size=1, max_size=4), junk)
def test_valid_frames_are_found_behind_any_junk(pieces, trailer):
    """A corrupted or fake header before a valid frame never hides the frame (the parser
    resumes its search at the next byte), in datagrams and in streams."""
    data, starts = b"", []
    for j, frame in pieces:
        data += j
        starts.append((len(data), frame))
        data += frame
    data += trailer
    frames, rejected = split_frames(data)
    check_split(data, frames, rejected)
    for at, frame in starts:
        assert recovered(data, frames, frame, at)
    frames, rejected, tail = split_frames(data, stream=True)
    check_split(data, frames, rejected, tail)
    for at, frame in starts:
        assert recovered(data, frames, frame, at) or at >= len(data) - len(tail)


@FAST
@given(hot_frame(), st.data())
def test_truncated_frames_are_rejected_in_datagrams_and_kept_in_streams(frame, data):
    cut = data.draw(st.integers(0, len(frame) - 1))
    part = frame[:cut]
    frames, rejected = split_frames(part)
    assert frames == [] and rejected == cut
    frames, rejected, tail = split_frames(part, stream=True)
    assert frames == [] and rejected == 0 and tail == part
    reader = FrameReader(stream=True)
    assert reader.feed("peer", part) == ([], 0)
    frames, rejected = reader.feed("peer", frame[cut:])
    assert [f.raw for f in frames] == [frame] and rejected == 0


@FAST
@given(hot_frame(), st.data())
def test_a_single_bit_flip_is_always_rejected(frame, data):
    """CRC-16 catches every single-bit error: the damaged frame is never returned."""
    bit = data.draw(st.integers(0, 8 * len(frame) - 1))
    damaged = bytearray(frame)
    damaged[bit // 8] ^= 1 << (bit % 8)
    damaged = bytes(damaged)
    for stream in (False, True):
        frames, rejected, *tail = split_frames(damaged, stream=stream)
        check_split(damaged, frames, rejected, *tail)
        assert all(not f.raw.startswith(damaged[:10]) or f.raw == frame for f in frames)
        assert frame not in [f.raw for f in frames]
        assert rejected > 0 or (tail and tail[0])


@FAST
@given(st.lists(hot_frame(), min_size=1, max_size=3), st.data())
def test_bit_flipped_and_cut_frames_yield_only_valid_frames(frames_in, data):
    blob = bytearray(b"".join(frames_in))
    for _ in range(data.draw(st.integers(1, 12))):
        bit = data.draw(st.integers(0, 8 * len(blob) - 1))
        blob[bit // 8] ^= 1 << (bit % 8)
    blob = bytes(blob[:data.draw(st.integers(0, len(blob)))])
    frames, rejected = split_frames(blob)
    check_split(blob, frames, rejected)
    reader = FrameReader(stream=False)
    assert reader.feed(("127.0.0.1", 1), blob) == (frames, rejected)


@FAST
@given(st.lists(st.tuples(st.sampled_from(["a", "b"]), junk, valid_frame), min_size=1,
                max_size=6), st.data())
def test_stream_reader_reassembles_each_peer_from_any_chunking(pieces, data):
    """Two interleaved byte streams cut at arbitrary places: each peer's frames come out
    whole, in order, and the rejected count is exactly the junk that held no frame."""
    streams = {"a": b"", "b": b""}
    expected = {"a": [], "b": []}
    for peer, j, frame in pieces:
        streams[peer] += j
        expected[peer].append((len(streams[peer]), frame))
        streams[peer] += frame
    chunks = []
    for peer, stream in streams.items():
        pos = 0
        while pos < len(stream):
            n = data.draw(st.integers(1, 300))
            chunks.append((peer, stream[pos:pos + n]))
            pos += n
    order = data.draw(st.permutations(range(len(chunks))))
    # keep each peer's chunks in order, interleave the peers arbitrarily
    by_peer = {"a": [c for c in chunks if c[0] == "a"], "b": [c for c in chunks if c[0] == "b"]}
    merged = []
    for k in order:
        peer = chunks[k][0]
        merged.append(by_peer[peer].pop(0))
    reader = FrameReader(stream=True)
    got = {"a": [], "b": []}
    rejected = {"a": 0, "b": 0}
    for peer, chunk in merged:
        frames, r = reader.feed(peer, chunk)
        got[peer] += frames
        rejected[peer] += r
    for peer, stream in streams.items():
        tail = reader.tails.get(peer, b"")
        check_split(stream, got[peer], rejected[peer], tail)
        for at, frame in expected[peer]:
            assert recovered(stream, got[peer], frame, at) or at >= len(stream) - len(tail)


def test_a_fake_header_does_not_swallow_the_next_frame():
    """Regression: a start marker followed by a header naming an unknown message used to be
    returned as a frame, unchecked, consuming the valid ODOMETRY behind it."""
    odo = Odometry(123, (1.0, 2.0, 3.0), (1.0, 0.0, 0.0, 0.0), (0.0,) * 3, (0.0,) * 3)
    frame = pack_odometry(odo, 1, 1, 200)
    fake = bytes([0xFD, 200, 0, 0, 0, 0, 0, 0x12, 0x34, 0x56])
    frames, rejected = split_frames(fake + frame + bytes(200))
    assert [f.raw for f in frames] == [frame] and rejected == len(fake) + 200
    frames, rejected, tail = split_frames(fake + frame, stream=True)
    assert [f.raw for f in frames] == [frame] and rejected == len(fake) and tail == b""
    flagged = bytearray(frame)
    flagged[2] = 0x80  # an incompatibility flag nobody defines: dropped, as the spec says
    assert split_frames(bytes(flagged)) == ([], len(frame))


# ----------------------------------------------------------------------------------------
# The mission protocol, vehicle side
# ----------------------------------------------------------------------------------------

VEHICLE = (1, M.MAV_COMP_ID_AUTOPILOT1)
GCS = (255, M.MAV_COMP_ID_MISSIONPLANNER)
OTHER = (254, M.MAV_COMP_ID_MISSIONPLANNER)
SUPPORTED = [16, 19, 21, 22, 31000, 31001]
KINDS = ["mission_count", "mission_item_int", "mission_item", "mission_request_list",
         "mission_request_int", "mission_request", "mission_ack", "mission_clear_all",
         "mission_set_current", "mission_write_partial_list", "mission_request_partial_list",
         "mission_current", "mission_item_reached"]
_INT_RANGES = {"uint8_t": (0, 255), "int8_t": (-128, 127), "uint16_t": (0, 65535),
               "int16_t": (-32768, 32767), "uint32_t": (0, 2**32 - 1),
               "int32_t": (-2**31, 2**31 - 1)}
small_f32 = st.one_of(st.floats(-50, 50, width=32), st.sampled_from([0.0, 1.0, 10.0, math.nan]))
any_f32 = st.one_of(small_f32, f32, st.sampled_from([math.inf, -math.inf, 3.4e38, -3.4e38,
                                                     1e-45]))


def field_strategy(name: str, ctype: str) -> st.SearchStrategy:
    """Random values for a field, biased towards the values that reach deep states."""
    if ctype == "float":
        return any_f32
    lo, hi = _INT_RANGES[ctype]
    anything = st.integers(lo, hi)
    biased = {
        "target_system": st.sampled_from([0, 1, 1, 1, 2, 255]),
        "target_component": st.sampled_from([0, 1, 1, 1, 190]),
        "mission_type": st.sampled_from([0, 0, 0, 0, 1, 2, 255]),
        "count": st.integers(0, 5),
        "seq": st.integers(0, 5),
        "frame": st.sampled_from([1, 1, 1, 0, 8]),
        "command": st.sampled_from(SUPPORTED),
        "type": st.sampled_from([0, 0, 1, 13, 15]),
        "x": st.integers(-50_000, 50_000),
        "y": st.integers(-50_000, 50_000),
    }.get(name)
    return anything if biased is None else st.one_of(biased, biased, anything)


@st.composite
def mission_message(draw):
    kind = draw(st.sampled_from(KINDS))
    cls = getattr(M, f"MAVLink_{kind}_message")
    values = {name: draw(field_strategy(name, ctype))
              for name, ctype in zip(cls.fieldnames, cls.fieldtypes, strict=True)}
    src = draw(st.sampled_from([GCS, GCS, GCS, OTHER, (1, 1), (0, 0)]))
    return ("msg", src, cls(**values))


@st.composite
def clean_upload(draw):
    """A whole upload of 1-4 plausible items from one GCS, each message possibly dropped
    or duplicated, then optionally a few messages re-sent out of order."""
    src = draw(st.sampled_from([GCS, OTHER]))
    n = draw(st.integers(1, 4))
    out = [("msg", src, M.MAVLink_mission_count_message(*VEHICLE, n, 0))]
    for seq in range(n):
        x, y = draw(st.integers(-20_000, 20_000)), draw(st.integers(-20_000, 20_000))
        msg = M.MAVLink_mission_item_int_message(
            *VEHICLE, seq, 1, draw(st.sampled_from([16, 19, 22])), int(seq == 0), 1,
            draw(st.sampled_from([0.0, 1.0, math.nan, -1.0])), 0.0, 0.0,
            draw(st.sampled_from([math.nan, 0.0, 90.0])), x, y,
            draw(st.sampled_from([-3.0, -1.0, math.inf])), 0)
        for _ in range(draw(st.sampled_from([1, 1, 1, 0, 2]))):
            out.append(("msg", src, msg))
    if draw(st.booleans()):
        out += draw(st.permutations(out))[:draw(st.integers(0, 3))]
    return out


actions = st.lists(st.one_of(
    mission_message(), mission_message(), mission_message(),
    st.tuples(st.just("tick"), st.sampled_from([0.0, 0.1, 0.3, 2.0])),
    clean_upload().map(lambda seq: ("batch", seq)),
), max_size=40)


def _through_wire(msg, src):
    return parser().decode(bytearray(pack(encoder(*src), msg)))


def _item_key(it: MissionItem):
    return tuple("nan" if isinstance(v, float) and math.isnan(v) else v for v in it)


def _initial_server() -> MissionServer:
    server = MissionServer(*VEHICLE, MissionLimits())
    items = tuple(MissionItem(i, 1, 16, int(i == 0), 1, 0.0, 0.0, 0.0, math.nan,
                              1000 * i, -1000 * i, -2.0) for i in range(3))
    server._replace(items)  # as after an accepted upload
    return server


@settings(max_examples=250, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(actions)
def test_mission_server_survives_any_mission_messages(script):
    """Random mission messages (any fields: NaN, infinities, huge ints, other targets, other
    senders, out-of-order seqs), interleaved with time: handle() and tick() never raise,
    every answer encodes and goes to the sender, and the stored mission changes only with
    a MISSION_ACK MAV_MISSION_ACCEPTED, to a mission that validates and that was sent."""
    server = _initial_server()
    changes = []
    server.on_mission_changed = changes.append
    now = 0.0
    sent_items: dict[tuple[int, int], set] = {}
    flat = []
    for action in script:
        flat += action[1] if action[0] == "batch" else [action]
    vehicle = encoder(*VEHICLE)
    observed = 0
    for action in flat:
        before = server.mission
        if action[0] == "tick":
            now += action[1]
            replies = server.tick(now)
            assert server.mission == before
            src = None
        else:
            _, src, msg = action
            now += 0.001
            decoded = _through_wire(msg, src)
            if decoded.get_type() in ("MISSION_ITEM_INT", "MISSION_ITEM"):
                sent_items.setdefault(src, set()).add(
                    _item_key(item_from_message(decoded)._replace(mission_type=0)))
            replies = server.handle(decoded, now)
        for reply in replies:
            back = _through_wire(reply, VEHICLE)
            pack(vehicle, reply)
            if back.get_type() == "STATUSTEXT":  # a refusal's reason, broadcast
                assert replies[-1].get_type() == "MISSION_ACK" and back.text
            elif src is not None:
                assert (back.target_system, back.target_component) == src
        if server.mission != before:
            observed += 1
            event("mission replaced" if server.mission else "mission cleared")
            acks = [r for r in replies if r.get_type() == "MISSION_ACK"]
            assert [a.type for a in acks] == [M.MAV_MISSION_ACCEPTED]
            assert validate_mission(server.mission, server.limits)[0] == M.MAV_MISSION_ACCEPTED
            for it in server.mission:
                assert _item_key(it) in sent_items[src]
    assert len(changes) >= observed  # the owner hears of every change


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(clean_upload(), st.lists(mission_message(), max_size=5))
def test_an_accepted_upload_stores_exactly_the_items_sent(upload, noise):
    """Whatever came before, an upload that ends in MAV_MISSION_ACCEPTED (to the uploader)
    leaves the mission equal to the items of that upload, in order; any other result is the
    validation's and leaves the mission as it was."""
    server = _initial_server()
    now = 0.0
    for _, src, msg in noise:
        now += 0.01
        server.handle(_through_wire(msg, src), now)
    src = upload[0][1]
    for _ in range(10):  # whatever upload the noise started times out (5 re-requests)
        now += 0.3
        server.tick(now)
    before = server.mission  # the noise may have cleared it (MISSION_COUNT 0, CLEAR_ALL)
    _, _, count_msg = upload[0]
    items = {m.seq: m for _, _, m in upload if m.get_type() == "MISSION_ITEM_INT"}
    assume(len(items) == count_msg.count)
    result = None
    for msg in [count_msg, *(items[s] for s in range(count_msg.count))]:
        now += 0.001
        for reply in server.handle(_through_wire(msg, src), now):
            if reply.get_type() == "MISSION_ACK":
                result = reply.type
    expected = tuple(item_from_message(_through_wire(items[s], src))._replace(mission_type=0)
                     for s in range(count_msg.count))
    event(f"upload result {result}")
    if result == M.MAV_MISSION_ACCEPTED:
        assert [_item_key(i) for i in server.mission] == [_item_key(i) for i in expected]
    else:
        assert result == validate_mission(expected, server.limits)[0]
        assert server.mission == before


# ----------------------------------------------------------------------------------------
# Mission files
# ----------------------------------------------------------------------------------------

_ITEM_INT = M.MAVLink_mission_item_int_message


def _packable(items: list[MissionItem]) -> None:
    """A parsed mission can be sent: every item encodes as MISSION_ITEM_INT."""
    mav = encoder(255, 190)
    for it in items:
        pack(mav, _ITEM_INT(1, 1, it.seq, it.frame, it.command, it.current, it.autocontinue,
                            it.param1, it.param2, it.param3, it.param4, it.x, it.y, it.z, 0))


def _parse_only_mission_errors(parse, text: str) -> None:
    try:
        items = parse(text)
    except MissionFileError:
        return
    _packable(items)


@FAST
@given(st.text(max_size=400))
def test_mission_files_arbitrary_text_raises_only_mission_file_error(text):
    _parse_only_mission_errors(parse_wpl, text)
    _parse_only_mission_errors(parse_toml, text)
    _parse_only_mission_errors(parse_wpl, "QGC WPL 110\n" + text)


token = st.one_of(
    st.sampled_from(["0", "1", "-1", "16", "31001", "255", "256", "65535", "65536", "nan",
                     "inf", "-inf", "1e39", "-1e39", "3.4e38", "1e300", "2147483648",
                     "99999999999999999999", "0.5", "", "x", "1_0", "0x10", "١"]),
    st.integers().map(str), st.floats().map(repr), st.text(max_size=5))


@FAST
@given(st.lists(st.lists(token, min_size=10, max_size=13), max_size=5),
       st.sampled_from(["\t", " "]))
def test_wpl_lines_of_any_fields_raise_only_mission_file_error(rows, sep):
    text = "QGC WPL 110\n" + "\n".join(sep.join(r) for r in rows)
    _parse_only_mission_errors(parse_wpl, text)


toml_value = st.one_of(
    st.sampled_from(['"raw"', '"waypoint"', '"takeoff"', '"loiter"', '"land"', '"keyframe"',
                     '"figure_eight"', '"jump"', "true", "nan", "inf", "-inf", "1e39",
                     "99999999999999999999999", "1", "0", "-1", "16", "70000", "3.5",
                     "[0, 0, 0]", "[0, 0, 0, 0]", "[1e39, 0, 0]", "[inf, 0, 0]",
                     '[0, "a", 0]', "[true, 0, 0]", "[[1]]", "{a = 1}", "[]",
                     '"dqflight-mission-1"', "[1e300, 0, 0, 0]"]),
    st.integers().map(str), st.floats().map(lambda f: repr(f).replace("e+", "e")))
toml_key = st.sampled_from(["type", "command", "frame", "autocontinue", "params", "x", "y",
                            "z", "position_ned_m", "hold_s", "time_s", "yaw_deg",
                            "altitude_ned_z_m", "climb_time_s", "amplitude_m", "duration_s",
                            "axis_ned", "rotvec_ned_frd_rad", "speed"])


@FAST
@given(st.lists(st.dictionaries(toml_key, toml_value, max_size=8), max_size=4),
       st.sampled_from(["", 'format = "dqflight-mission-1"\n', "format = 2\n", "item = 5\n",
                        'item = "x"\n', "item = [1, 2]\n", "other = 1\n"]))
def test_toml_items_of_any_keys_and_values_raise_only_mission_file_error(tables, head):
    text = head + "".join("[[item]]\n" + "".join(f"{k} = {v}\n" for k, v in t.items())
                          for t in tables)
    _parse_only_mission_errors(parse_toml, text)


@settings(max_examples=50, deadline=None)
@given(st.binary(max_size=200))
def test_reading_any_file_raises_only_mission_file_error(blob):
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "m.waypoints"
        path.write_bytes(blob)
        try:
            _packable(read_mission(path))
        except MissionFileError:
            pass


def test_mission_file_regressions():
    """Inputs that used to raise other exceptions, or parse into items that cannot be sent
    (the upload then failed with struct.error or OverflowError)."""
    bad_toml = [
        "item = 5", 'item = "abc"', "item = [1]", "a = " + "[" * 2000 + "]" * 2000,
        '[[item]]\ntype = "raw"\ncommand = "x"\nparams = [0, 0, 0, 0]\nx = 0\ny = 0\nz = 0',
        '[[item]]\ntype = "raw"\ncommand = 16\nparams = [0, 0, 0, 0]\nx = inf\ny = 0\nz = 0',
        '[[item]]\ntype = "raw"\ncommand = 16\nframe = [1]\nparams = [0, 0, 0, 0]\nx = 0\n'
        "y = 0\nz = 0",
        '[[item]]\ntype = "raw"\ncommand = 99999999\nparams = [0, 0, 0, 0]\nx = 0\ny = 0\n'
        "z = 0",
        '[[item]]\ntype = "waypoint"\nposition_ned_m = [1e300, 0, 0]\nhold_s = 0',
        '[[item]]\ntype = "waypoint"\nposition_ned_m = [0, 0, 1e39]\nhold_s = 0',
    ]
    for text in bad_toml:
        try:
            parse_toml(text)
        except MissionFileError:
            continue
        raise AssertionError(f"accepted: {text[:60]!r}")
    bad_wpl = ["0\t0\t1\t99999999\t0\t0\t0\t0\t0\t0\t0\t1", "-1\t0\t1\t16\t0\t0\t0\t0\t0\t0\t0\t1",
               "0\t0\t1\t16\t1e39\t0\t0\t0\t0\t0\t0\t1", "0\t300\t1\t16\t0\t0\t0\t0\t0\t0\t0\t1"]
    for line in bad_wpl:
        try:
            parse_wpl("QGC WPL 110\n" + line)
        except MissionFileError:
            continue
        raise AssertionError(f"accepted: {line!r}")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "m.toml"
        path.write_bytes(b"\xff\xfe\x00binary")
        try:
            read_mission(path)
        except MissionFileError as exc:
            assert "not a text file" in str(exc)
        else:
            raise AssertionError("binary file accepted")
