"""What the ground station has heard from its vehicle: the latest of each message, when,
the last status texts; listening for a while, with requests for messages a vehicle sends
only when asked (MAV_CMD_REQUEST_MESSAGE)."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

from common.wire.mavlink import MAV
from gcs.vehicle_link.session import Session

M = MAV


@dataclass
class Snapshot:
    """The latest of each message type from the vehicle, when each was heard (monotonic
    seconds), the last status texts (and the last failsafe text: severity CRITICAL or
    worse), and link statistics."""

    messages: dict[str, Any] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=dict)
    heard: dict[str, float] = field(default_factory=dict)
    received: int = 0
    lost: int = 0
    started: float = field(default_factory=time.monotonic)
    texts: list[str] = field(default_factory=list)
    failsafe_text: str = ""
    rate_samples: list[tuple[float, int]] = field(default_factory=list)  # (when, received)

    def update(self, msg: Any, now: float | None = None) -> None:
        kind = msg.get_type()
        if kind == "BAD_DATA":
            return
        if kind == "STATUSTEXT":
            self.texts = [*self.texts[-9:], msg.text]
            if msg.severity <= M.MAV_SEVERITY_CRITICAL:
                self.failsafe_text = msg.text
        self.messages[kind] = msg
        self.counts[kind] = self.counts.get(kind, 0) + 1
        self.heard[kind] = time.monotonic() if now is None else now

    def get(self, kind: str) -> Any:
        return self.messages.get(kind)

    def age(self, kind: str, now: float) -> float | None:
        """Seconds since the last message of this type, None if never heard."""
        t = self.heard.get(kind)
        return None if t is None else now - t


def link_quality(session: Session) -> tuple[float, int, int]:
    """(loss percent, messages received, messages lost) from sequence numbers."""
    conn = session.conn
    return conn.packet_loss(), conn.mav_count, conn.mav_loss


def collect(session: Session, snapshot: Snapshot, seconds: float) -> Snapshot:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        msg = session.recv(None, timeout=max(0.01, deadline - time.monotonic()))
        if session.from_autopilot(msg):
            snapshot.update(msg)
    return snapshot




def collect_requested(session: Session, snapshot: Snapshot, requests: dict[str, int],
                      seconds: float, patience: float) -> Snapshot:
    """Listen for `seconds`, and on until each requested message has come (asked again
    every second) or its request was refused, at most `patience` seconds longer. The
    requests go out together and their answers are read with everything else: waiting for
    one request's COMMAND_ACK would drop the message another one brought."""
    s = session
    start = time.monotonic()
    wanted = dict(requests)
    asked_at = -math.inf
    while True:
        now = time.monotonic()
        missing = {name: i for name, i in wanted.items() if snapshot.get(name) is None}
        if (now - start >= seconds and not missing) or now - start >= seconds + patience:
            return snapshot
        if missing and now - asked_at >= 1.0:
            for msg_id in missing.values():
                s.send(M.MAVLink_command_long_message(s.target_system, s.target_component,
                                                      M.MAV_CMD_REQUEST_MESSAGE, 0, msg_id,
                                                      0, 0, 0, 0, 0, 0))
            asked_at = now
        msg = s.recv(None, timeout=0.05)
        if not s.from_autopilot(msg):
            continue
        snapshot.update(msg)
        if msg.get_type() == "COMMAND_ACK" and msg.command == M.MAV_CMD_REQUEST_MESSAGE and \
                s.addressed_to_me(msg) and \
                msg.result not in (M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_IN_PROGRESS):
            wanted = {}  # an ACK does not say which request it answers: stop asking
