"""A ground-station session on one MAVLink link: connect, wait for the vehicle's heartbeat,
send our own heartbeat from a thread, send commands and wait for their ACKs, log a tlog.

Wall-clock timeouts are fine here: the GCS faces people and links, not the lockstep path.
"""

from __future__ import annotations

import struct
import threading
import time
from pathlib import Path

from pymavlink import mavutil

import common.mavlink  # noqa: F401  (pins MAVLink 2 before mavutil is imported)
from common.mavlink import GCS_SYSID, MAV, MAV_COMP_ID_MISSIONPLANNER

M = MAV


class GcsError(RuntimeError):
    """A vehicle that does not answer, refuses a command, or a link that fails."""


class Tlog:
    """A telemetry log as MAVProxy and QGroundControl write it: each message preceded by its
    wall-clock time in microseconds (big-endian uint64). Unbuffered: every complete record
    is in the file at once."""

    def __init__(self, path: Path) -> None:
        self.fh = path.open("wb", buffering=0)
        self.lock = threading.Lock()

    def write(self, msg) -> None:
        if msg.get_type() == "BAD_DATA":
            return
        usec = int(time.time() * 1e6) & ~3
        with self.lock:
            self.fh.write(struct.pack(">Q", usec) + msg.get_msgbuf())

    def close(self) -> None:
        self.fh.close()


class MavZenoh(mavutil.mavfile):
    """pymavlink's connection interface over a Zenoh link (ground-station role)."""

    def __init__(self, url: str, source_system: int, source_component: int,
                 vehicle: int = 0) -> None:
        from common.links import open_link
        from common.zenoh_link import ZenohLink

        link = open_link(url, role="gcs", system_id=vehicle)
        assert isinstance(link, ZenohLink)
        self.link = link
        mavutil.mavfile.__init__(self, self.link.fileno(), url, source_system=source_system,
                                 source_component=source_component, use_native=False)
        self._buf = b""

    def recv(self, n=None) -> bytes:
        if not self._buf:
            self._buf = b"".join(data for _, data in self.link.recv())
        data, self._buf = self._buf, b""
        return data

    def write(self, buf: bytes) -> None:
        self.link.send(buf)

    def set_target(self, system_id: int) -> None:
        self.link.set_target(system_id)

    @property
    def vehicles(self) -> set[int]:
        return set(self.link.vehicles)

    def close(self) -> None:
        self.link.close()


def connect(url: str, system_id: int = GCS_SYSID, vehicle: int = 0):
    """A pymavlink connection for any link URL of this project (zenoh: included)."""
    if url.startswith("zenoh:"):
        return MavZenoh(url, system_id, MAV_COMP_ID_MISSIONPLANNER, vehicle)
    return mavutil.mavlink_connection(url, source_system=system_id,
                                      source_component=MAV_COMP_ID_MISSIONPLANNER,
                                      dialect="common", autoreconnect=True)


class Session:
    def __init__(self, url: str, *, tlog: Path | None = None, system_id: int = GCS_SYSID,
                 heartbeat_hz: float = 1.0, vehicle: int = 0,
                 signing_key: bytes | None = None) -> None:
        self.conn = connect(url, system_id, vehicle)
        if signing_key is not None:  # sign what we send, refuse what is not signed
            self.conn.setup_signing(signing_key, sign_outgoing=True,
                                    allow_unsigned_callback=None)
        self.tlog = Tlog(tlog) if tlog else None
        if self.tlog is not None:
            received = self.conn.post_message

            def post_message(msg, _received=received, _log=self.tlog):
                _log.write(msg)  # every message heard, whatever the caller waits for
                _received(msg)

            self.conn.post_message = post_message
        self.lock = threading.Lock()
        self.target_system = 0
        self.target_component = 0
        self._stop = threading.Event()
        self._period = 1.0 / heartbeat_hz
        self._thread = threading.Thread(target=self._heartbeats, name="gcs-heartbeat",
                                        daemon=True)
        self._thread.start()

    def heartbeat(self) -> None:
        self.send(M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0,
                                              M.MAV_STATE_ACTIVE, 3))

    def _heartbeats(self) -> None:
        while not self._stop.is_set():
            if isinstance(self.conn, MavZenoh) and not self.target_system:
                self._stop.wait(0.1)  # over Zenoh, heartbeats go to a chosen vehicle
                continue
            self.heartbeat()
            self._stop.wait(self._period)

    def send(self, msg) -> None:
        with self.lock:
            self.conn.mav.send(msg)
        if self.tlog is not None:
            self.tlog.write(msg)

    def recv(self, types: list[str] | None = None, timeout: float = 1.0):
        return self.conn.recv_match(type=types, blocking=True, timeout=timeout)

    def wait_vehicle(self, timeout: float = 10.0, system_id: int | None = None) -> None:
        """Wait for an autopilot's heartbeat; pick its system id (or the one asked for)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            msg = self.recv(["HEARTBEAT"], timeout=max(0.05, deadline - time.monotonic()))
            if msg is None or msg.autopilot == M.MAV_AUTOPILOT_INVALID:
                continue
            if system_id is not None and msg.get_srcSystem() != system_id:
                continue
            self.target_system = msg.get_srcSystem()
            self.target_component = msg.get_srcComponent()
            if isinstance(self.conn, MavZenoh):
                self.conn.set_target(self.target_system)
            self.heartbeat()  # announce ourselves now: a udpin link has only now a peer
            return
        raise GcsError(f"no vehicle heartbeat within {timeout:.0f} s")

    def command(self, command: int, *params: float, timeout: float = 1.0,
                retries: int = 3) -> int:
        """COMMAND_LONG with retries (confirmation incremented); returns MAV_RESULT."""
        p = [*params, *([0.0] * (7 - len(params)))]
        for confirmation in range(retries + 1):
            self.send(M.MAVLink_command_long_message(self.target_system, self.target_component,
                                                     command, confirmation, *p))
            deadline = time.monotonic() + timeout
            while time.monotonic() < deadline:
                ack = self.recv(["COMMAND_ACK"], timeout=max(0.01, deadline - time.monotonic()))
                if ack is not None and ack.command == command:
                    return ack.result
        raise GcsError(f"no COMMAND_ACK for command {command} after {retries + 1} tries")

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self.conn.close()
        if self.tlog is not None:
            self.tlog.close()
