"""Probes: after a sync, the FCU's answers are checked against what the inputs set."""

from __future__ import annotations

import math
import random
import secrets
import select
import socket
import time
from collections import Counter
from collections.abc import Callable, Iterator
from typing import Any

from benchmarks.fuzz.gcs_messages import (
    F32_MAX,
    GET_IV,
    INTERVALS_US,
    NOT_ANSWERED_IDS,
    PROBE_LINK_ID,
    PROBE_SYSID,
    REQUEST,
    REQUESTABLE_IDS,
    SET_IV,
    STREAM_IDS,
    f32,
    f32_step,
)
from benchmarks.fuzz.listener import LinkListener
from common.wire.mavlink import MAV, encoder, pack, parser, signing_timestamp
from fcu.edge.telemetry import (
    DEFAULT_INTERVALS_S,
    LINK_BUDGET_MSG_S,
    MAX_INTERVAL_US,
    MIN_INTERVAL_S,
    REQUESTABLE,
)
from fcu.params import SPECS as PARAM_SPECS

M = MAV


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
        self.outcomes: dict[str, Counter[str]] = {}
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

    def _datagrams(self, timeout: float) -> Iterator[bytes]:
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

    def recv(self, match: Callable[[Any], bool], timeout: float = 2.0) -> Any:
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

    def read_param(self, name: str) -> Any:
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

    def _count(self, seconds: float) -> Counter[int]:
        counts: Counter[int] = Counter()
        for data in self._datagrams(seconds):
            if len(data) >= 10 and data[0] == 0xFD and data[5] == 1:
                counts[data[7] | data[8] << 8 | data[9] << 16] += 1
        return counts

    def probe_streams(self) -> None:
        """Every requestable id answered (ACCEPTED) and no other; then every stream of link
        1 off, some asked at 1 kHz (the first fills the budget), and what streams read for a
        second: within the link's budget; then every stream back to its default."""
        bad: list[str] = []
        missing = self._requests_answered(bad) + self._streams_off(bad)
        fast = self.rng.sample(STREAM_IDS, self.rng.randint(3, len(STREAM_IDS)))
        accepted = []
        for msg_id in fast:
            self.command(SET_IV, float(msg_id), 1.0)  # 1 us: 1 kHz, if the budget allows
            if self.ack(SET_IV) == M.MAV_RESULT_ACCEPTED:
                accepted.append(msg_id)
        total = self._streams_within_budget(bad)
        self._streams_back(accepted, bad)
        ok = False if bad else None if missing else True
        self._outcome("streams", ok, "; ".join(bad[:4]) + f" ({missing} commands unanswered; "
                      f"asked at 1 us: {fast}, {total} stream msg/s)")

    def _requests_answered(self, bad: list[str]) -> int:
        """REQUEST_MESSAGE of every requestable id (ACCEPTED) and of others (UNSUPPORTED);
        wrong answers into `bad`; how many went unanswered."""
        missing = 0
        for msg_id in (*REQUESTABLE_IDS, *NOT_ANSWERED_IDS):
            self.command(REQUEST, float(msg_id))
            result = self.ack(REQUEST)
            want = M.MAV_RESULT_ACCEPTED if msg_id in REQUESTABLE else M.MAV_RESULT_UNSUPPORTED
            if result is None:
                missing += 1
            elif result != want:
                bad.append(f"REQUEST_MESSAGE({msg_id}): {result}, expected {want}")
        return missing

    def _streams_off(self, bad: list[str]) -> int:
        """Every stream turned off (always possible); refusals into `bad`; how many went
        unanswered."""
        missing = 0
        for msg_id in STREAM_IDS:  # turning a stream off is always possible
            self.command(SET_IV, float(msg_id), -1.0)
            result = self.ack(SET_IV)
            if result is None:
                missing += 1
            elif result != M.MAV_RESULT_ACCEPTED:
                bad.append(f"SET_MESSAGE_INTERVAL({msg_id}, -1): {result}, expected 0")
        return missing

    def _streams_within_budget(self, bad: list[str]) -> int:
        """The stream messages of one second, counted: over the link's budget, or one over
        1 kHz, into `bad`; their total."""
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
        return total

    def _streams_back(self, accepted: list[int], bad: list[str]) -> None:
        """The fast streams off, then every stream back to its default; refusals into
        `bad`."""
        for msg_id in (*accepted, *STREAM_IDS):  # the fast ones off, then all to default
            self.command(SET_IV, float(msg_id), -1.0 if msg_id in accepted else 0.0)
            accepted = [i for i in accepted if i != msg_id]
            result = self.ack(SET_IV)
            if result is not None and result != M.MAV_RESULT_ACCEPTED:
                bad.append(f"SET_MESSAGE_INTERVAL({msg_id}) back to its default: {result}")

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
