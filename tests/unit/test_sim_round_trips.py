"""The FCU's TIMESYNC round trips with the simulator (`SimBridge.round_trips`): an answer
that comes after its request's timeout is late, not lost; a simulator that never answers
is given up on; what else arrives is handed back in order."""

from __future__ import annotations

import os
from collections import deque

from common.links.base import Link
from common.links.url import parse_url
from common.wire.simlink import TIMESYNC_ID, pack_timesync, split_frames, unpack_timesync
from fcu.edge.sim_bridge import SimBridge

SYS = 1
FCU_COMP = 1
SITL_COMP = 51


class _Simulator(Link):
    """A simulator link that answers each TIMESYNC request as it is sent, except those the
    test holds back: a held answer goes out just before the next request's (a process
    preempted past the request's timeout, then delivering in order)."""

    def __init__(self, hold: set[int], silent: bool = False, extra: bytes = b"") -> None:
        self.url = parse_url("udpin:127.0.0.1:14560")
        self.hold = hold  # the requests (counted from 0) whose answers come late
        self.silent = silent
        self.requests = 0
        self.held: deque[bytes] = deque()
        self.ready: deque[bytes] = deque([extra] if extra else [])
        self.r, self.w = os.pipe()
        if extra:
            os.write(self.w, b"x")

    def filenos(self) -> list[int]:
        return [self.r]

    def send(self, data: bytes) -> None:
        frames, _ = split_frames(data)
        assert len(frames) == 1 and frames[0].msg_id == TIMESYNC_ID
        tc1, ts1 = unpack_timesync(frames[0].payload)
        assert tc1 == 0
        answer = pack_timesync(1, ts1, 0, SYS, SITL_COMP)
        n, self.requests = self.requests, self.requests + 1
        if self.silent:
            return
        if n in self.hold:
            self.held.append(answer)
            return
        while self.held:
            self._deliver(self.held.popleft())
        self._deliver(answer)

    def _deliver(self, data: bytes) -> None:
        self.ready.append(data)
        os.write(self.w, b"x")

    def recv(self, limit: int = 64) -> list[tuple[object, bytes]]:
        out: list[tuple[object, bytes]] = []
        while self.ready and len(out) < limit:
            out.append((("127.0.0.1", 1), self.ready.popleft()))
            os.read(self.r, 1)
        return out

    def close(self) -> None:
        os.close(self.r)
        os.close(self.w)


def _bridge(sim: _Simulator) -> SimBridge:
    return SimBridge(sim, SYS, FCU_COMP, lockstep=True, w_max=1000.0)


def test_an_answer_after_its_timeout_is_late_not_lost():
    sim = _Simulator(hold={2, 5})
    try:
        # each held answer costs one timeout; an answer sent at once must not outlast it
        # on a busy machine (at 5 ms one did)
        rt = _bridge(sim).round_trips(20, timeout_s=0.25)
    finally:
        sim.close()
    assert len(rt.samples_us) == 20 and rt.lost == 0 and rt.late == 2
    assert sim.requests == 22  # each held request was sent once, and 20 more were timed
    assert rt.other == []  # the late answers are the probe's own, not handed on
    assert rt.summary()["late"] == 2 and rt.summary()["lost"] == 0


def test_a_simulator_that_never_answers_is_given_up_on():
    sim = _Simulator(hold=set(), silent=True)
    try:
        rt = _bridge(sim).round_trips(20, timeout_s=0.002, max_lost=3)
    finally:
        sim.close()
    assert rt.samples_us == [] and rt.lost == 3 and rt.late == 0 and sim.requests == 3


def test_what_else_arrives_is_handed_back():
    state = pack_timesync(0, 7, 0, SYS, SITL_COMP)  # a request of the simulator's own
    sim = _Simulator(hold=set(), extra=state)
    try:
        rt = _bridge(sim).round_trips(5, timeout_s=0.01)
    finally:
        sim.close()
    assert len(rt.samples_us) == 5 and rt.lost == 0
    assert [data for _, data in rt.other] == [state]
