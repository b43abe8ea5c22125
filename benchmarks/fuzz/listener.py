"""The listening link: every datagram of the FCU's second GCS link with its kernel arrival
time."""

from __future__ import annotations

import itertools
import select
import socket
import struct
import threading
import time
from collections import Counter
from collections.abc import Callable
from typing import Any

from common.wire.mavlink import MAV, parser
from common.wire.modes import Mode
from fcu.edge.telemetry import DEFAULT_INTERVALS_S

M = MAV


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
        self.per_second: Counter[int] = Counter()  # int(t) -> datagrams
        self.streams_per_second: Counter[int] = Counter()
        self.by_type: Counter[int | None] = Counter()
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

    def summary(self, t1: float) -> dict[str, Any]:
        """The longest HEARTBEAT gap from the first heartbeat to `t1` (wall clock) and the
        messages per second received."""
        beats = self.heartbeats
        t0 = beats[0] if beats else self.created
        points = [t0, *(b for b in beats if t0 <= b <= t1), t1]
        gaps = [(b - a, a) for a, b in itertools.pairwise(points)]
        gap, gap_at = max(gaps)
        seconds = range(int(t0) + 1, int(t1))  # whole seconds only
        span = max(t1 - t0, 1e-9)
        # snapshots (one C-level copy each): the listener thread keeps counting meanwhile
        per_second, streams_per_second = dict(self.per_second), dict(self.streams_per_second)
        by_type = Counter(dict(self.by_type))
        total = sum(n for s, n in per_second.items() if t0 <= s + 0.5 <= t1)
        streams = sum(n for s, n in streams_per_second.items() if t0 <= s + 0.5 <= t1)
        names = {}
        for msgid, n in by_type.most_common(6):
            cls = M.mavlink_map.get(msgid) if msgid is not None else None
            names[cls.msgname if cls else "not MAVLink 2"] = round(n / span, 1)
        arms = sum(1 for a, b in itertools.pairwise(self.states) if a[1] != b[1])
        modes = sorted({m.name for _, _, c in self.states for m in Mode if m.custom_mode == c})
        return {"seconds": span, "heartbeats": len(beats), "gap_max_s": gap,
                "gap_at_s": gap_at - t0, "msg_s": total / span,
                "msg_s_max": max((per_second.get(s, 0) for s in seconds), default=0),
                "stream_msg_s": streams / span,
                "stream_msg_s_max": max((streams_per_second.get(s, 0) for s in seconds),
                                        default=0),
                "top_msg_s": names, "arm_changes": arms, "modes": modes,
                "internal_error_texts": sum(1 for _, x in self.texts if "internal error" in x)}

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self.sock.close()
