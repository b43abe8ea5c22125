"""A ground-station session on one MAVLink link: connect, wait for the vehicle's heartbeat,
send our own heartbeat from a thread, send commands and wait for their ACKs, log a tlog.

The link is one of `common.links` (the same URLs and transports as `fcu` and `sitl`);
`LinkFile` gives it pymavlink's connection interface (`recv_match`, `mav.send`, packet
loss), which the mission client and the tools built on pymavlink expect. pymavlink itself
only encodes and decodes (`common.wire.mavlink`).

The station decodes with pymavlink's `ardupilotmega` dialect, a superset of `common` (the
project's own processes speak common): ArduPilot's own messages (EKF_STATUS_REPORT, MEMINFO,
...) are then received and counted, not lost, and common messages decode the same.
`wait_vehicle` tells which autopilot answers (`gcs.autopilot`); `request_streams` asks it
for the telemetry a command needs, and `close` gives back what was changed.

Wall-clock timeouts are fine here: the GCS faces people and links, not the lockstep path.
How long an answer is waited for is `gcs.vehicle_link.patience`'s policy: `last_heard` is when any
message of the vehicle's autopilot (the component whose HEARTBEAT was taken) last came,
whoever read it.
"""

from __future__ import annotations

import collections
import select
import struct
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeGuard

from pymavlink import mavutil

import common.wire.mavlink  # noqa: F401  (pins MAVLink 2 for mavutil)
from common.links import Link, LinkUrl, TcpClientLink, open_link, parse_url
from common.wire.mavlink import GCS_SYSID, MAV, MAV_COMP_ID_MISSIONPLANNER
from gcs.autopilot import Autopilot, autopilot_of
from gcs.autopilot import streams as _streams
from gcs.autopilot.dialect import STATION_DIALECT as DIALECT
from gcs.vehicle_link.patience import COMMAND, Wait, from_target

M = MAV
# HEARTBEAT types that are components or stations, never a vehicle's autopilot (as
# QGroundControl ignores them when it looks for vehicles)
NOT_A_VEHICLE = frozenset({
    M.MAV_TYPE_GCS, M.MAV_TYPE_ONBOARD_CONTROLLER, M.MAV_TYPE_GIMBAL, M.MAV_TYPE_ADSB,
    M.MAV_TYPE_CAMERA, M.MAV_TYPE_CHARGING_STATION, M.MAV_TYPE_FLARM, M.MAV_TYPE_SERVO,
    M.MAV_TYPE_ODID, M.MAV_TYPE_BATTERY, M.MAV_TYPE_PARACHUTE, M.MAV_TYPE_LOG,
    M.MAV_TYPE_OSD, M.MAV_TYPE_IMU, M.MAV_TYPE_GPS, M.MAV_TYPE_WINCH,
    M.MAV_TYPE_ILLUMINATOR, M.MAV_TYPE_GRIPPER})
TCP_CONNECT_S = 3.0  # a tcp: link that has not connected by then is reported, exit 1
TEXTS_KEPT = 256  # the latest STATUSTEXTs heard, with when (Session.texts)
REFUSAL_TEXT_S = 0.3  # after a refusal, how long to listen for the STATUSTEXT saying why
MAX_PARSERS = 64  # one parser per peer (byte stream); the oldest goes beyond this
_COMMANDS = (MAV.MAVLINK_MSG_ID_COMMAND_LONG, MAV.MAVLINK_MSG_ID_COMMAND_INT,
             MAV.MAVLINK_MSG_ID_SET_MODE)  # they change the state a HEARTBEAT reports

if TYPE_CHECKING:
    class _MavFile:
        """What LinkFile and its users take from pymavlink's untyped `mavfile` (messages
        are pymavlink's, Any); any other attribute is Any too."""

        mav: Any
        messages: dict[str, Any]
        mav_count: int
        mav_loss: int
        post_message: Callable[[Any], None]

        def __init__(self, fd: int | None, address: str, source_system: int = 255,
                     source_component: int = 0, notimestamps: bool = False,
                     input: bool = True, use_native: bool = False) -> None: ...
        def pre_message(self) -> None: ...
        def recv_match(self, condition: str | None = None,
                       type: str | list[str] | None = None, blocking: bool = False,
                       timeout: float | None = None) -> Any: ...
        def setup_signing(self, secret_key: bytes, sign_outgoing: bool = True,
                          allow_unsigned_callback: Callable[..., bool] | None = None,
                          initial_timestamp: int | None = None,
                          link_id: int | None = None) -> None: ...
        def packet_loss(self) -> float: ...
        def __getattr__(self, name: str) -> Any: ...
else:
    _MavFile = mavutil.mavfile


class GcsError(RuntimeError):
    """A vehicle that does not answer, refuses a command, or a link that fails."""


class Tlog:
    """A telemetry log as MAVProxy and QGroundControl write it: each message preceded by its
    wall-clock time in microseconds (big-endian uint64). Unbuffered: every complete record
    is in the file at once. The stamps never go back: each is taken under the lock that
    orders the writes (the heartbeat thread, the set-point stream and the reader all write),
    from the wall clock at opening plus the monotonic time since, so a wall-clock step does
    not reorder them. `records` counts the records written."""

    def __init__(self, path: Path) -> None:
        self.fh = path.open("wb", buffering=0)
        self.lock = threading.Lock()
        self.records = 0
        self._wall0_us = int(time.time() * 1e6)
        self._mono0_ns = time.monotonic_ns()
        self._last_us = 0

    def write(self, msg: Any) -> None:
        if msg.get_type() == "BAD_DATA":
            return
        with self.lock:
            usec = self._wall0_us + (time.monotonic_ns() - self._mono0_ns) // 1000
            usec = max(usec & ~3, self._last_us)
            self._last_us = usec
            self.fh.write(struct.pack(">Q", usec) + msg.get_msgbuf())
            self.records += 1

    def close(self) -> None:
        self.fh.close()


class LinkFile(_MavFile):
    """pymavlink's connection interface over a `common.links.Link`: each peer (a TCP
    client, a UDP sender) has its own parser, so that streams never mix; sends and reads
    are serialised (the heartbeat thread sends while the caller reads)."""

    def __init__(self, link: Link, source_system: int, source_component: int) -> None:
        self.link = link
        self._io = threading.Lock()
        self._queue: collections.deque[Any] = collections.deque()
        self._parsers: dict[object, DIALECT.MAVLink] = {}
        fd = link.fileno()
        _MavFile.__init__(self, fd if fd >= 0 else None, str(link.url),
                                 source_system=source_system,
                                 source_component=source_component, use_native=False)
        # MAVLink 2, ardupilotmega (common and more), whatever mavutil's default is
        self.mav = DIALECT.MAVLink(self, srcSystem=source_system,
                                   srcComponent=source_component, use_native=False)
        self.mav.robust_parsing = True

    def _parser(self, peer: object) -> DIALECT.MAVLink:
        parser = self._parsers.get(peer)
        if parser is None:
            if len(self._parsers) >= MAX_PARSERS:
                del self._parsers[next(iter(self._parsers))]
            parser = DIALECT.MAVLink(None, srcSystem=0, srcComponent=0, use_native=False)
            parser.robust_parsing = True
            parser.signing = self.mav.signing  # one key and replay record for the link
            self._parsers[peer] = parser
        return parser

    def _fill(self) -> None:
        with self._io:
            chunks = self.link.recv()
        for peer, data in chunks:
            msgs = self._parser(peer).parse_buffer(data)
            if msgs:
                self._queue.extend(msgs)

    def recv_msg(self) -> Any:
        self.pre_message()
        if not self._queue:
            self._fill()
        if not self._queue:
            return None
        msg = self._queue.popleft()
        self.post_message(msg)
        return msg

    def recv(self, n: int | None = None) -> bytes:
        raise NotImplementedError("LinkFile decodes per peer: use recv_msg/recv_match")

    def select(self, timeout: float) -> bool:
        if self._queue:
            return True
        with self._io:
            fds = self.link.filenos()
        if not fds:
            time.sleep(min(timeout, 0.05))
            return False
        try:
            return bool(select.select(fds, [], [], timeout)[0])
        except (OSError, ValueError):  # a descriptor closed meanwhile (reconnection)
            return False

    def write(self, buf: bytes) -> None:
        with self._io:
            self.link.send(bytes(buf))

    @property
    def needs_target(self) -> bool:
        """Zenoh: heartbeats and commands go to one chosen vehicle's key."""
        return hasattr(self.link, "set_target")

    def set_target(self, system_id: int) -> None:
        set_target = getattr(self.link, "set_target", None)  # Zenoh links have it
        if set_target is not None:
            set_target(system_id)

    @property
    def vehicles(self) -> set[int] | None:
        """The vehicles alive on the link where it knows (Zenoh liveliness), else None."""
        live = getattr(self.link, "vehicles", None)
        return None if live is None else set(live)

    def close(self) -> None:
        with self._io:
            self.link.close()


def connect(url: str | LinkUrl, system_id: int = GCS_SYSID, vehicle: int = 0) -> LinkFile:
    """A pymavlink-style connection over any link URL of this project (common.links).

    Raises LinkError for a URL, device or port that cannot be used (exit status 2) and
    LinkUnavailable for a tcp: server that refuses or does not answer (exit status 1)."""
    parsed = url if isinstance(url, LinkUrl) else parse_url(url)
    link = open_link(parsed, role="gcs", system_id=vehicle)
    if isinstance(link, TcpClientLink):
        try:
            link.wait_connected(TCP_CONNECT_S)
        except BaseException:
            link.close()
            raise
    return LinkFile(link, system_id, MAV_COMP_ID_MISSIONPLANNER)


class Session:
    def __init__(self, url: str, *, tlog: Path | None = None, system_id: int = GCS_SYSID,
                 heartbeat_hz: float = 1.0, vehicle: int = 0,
                 signing_key: bytes | None = None) -> None:
        self.conn = connect(url, system_id, vehicle)
        if signing_key is not None:  # sign what we send, refuse what is not signed
            self.conn.setup_signing(signing_key, sign_outgoing=True,
                                    allow_unsigned_callback=None)
        try:
            self.tlog = Tlog(tlog) if tlog else None
        except OSError:
            self.conn.close()
            raise
        # (monotonic s, system id, component id, text) of the latest STATUSTEXTs heard
        self.texts: collections.deque[tuple[float, int, int, str]] = \
            collections.deque(maxlen=TEXTS_KEPT)
        received = self.conn.post_message

        def post_message(msg: Any, _received: Callable[[Any], None] = received,
                         _log: Tlog | None = self.tlog) -> None:
            if _log is not None:
                _log.write(msg)  # every message heard, whatever the caller waits for
            if msg.get_type() == "STATUSTEXT":  # kept whoever reads the link meanwhile
                self.texts.append((time.monotonic(), msg.get_srcSystem(),
                                   msg.get_srcComponent(), str(msg.text)))
            if self.target_system and self.from_autopilot(msg):
                # the vehicle's autopilot is alive (gcs.vehicle_link.patience): not another
                # component of its system (a companion computer's heartbeat goes on when
                # the autopilot has stopped)
                self.last_heard = time.monotonic()
            _received(msg)

        self.conn.post_message = post_message
        self.lock = threading.Lock()
        self.target_system = 0
        self.target_component = 0
        self.last_texts: list[str] = []  # STATUSTEXTs that came with the last command's ACK
        self.heartbeat_msg: Any = None  # the vehicle heartbeat that wait_vehicle took
        self.heartbeat_at = 0.0  # and when (monotonic seconds)
        self.last_heard = 0.0  # the latest message of the target (monotonic s)
        self.commanded_at = 0.0  # the latest command sent (wall clock, as pymavlink stamps)
        self.command_sends = 0  # how often the latest `command` was sent (2 and more: re-sent)
        self.autopilot: Autopilot | None = None  # which autopilot that heartbeat came from
        self._streams = _streams.Streams()  # what request_streams changed on the link
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
            if self.conn.needs_target and not self.target_system:
                self._stop.wait(0.1)  # over Zenoh, heartbeats go to a chosen vehicle
                continue
            self.heartbeat()
            self._stop.wait(self._period)

    def send(self, msg: Any) -> None:
        if msg.get_msgId() in _COMMANDS:  # what the vehicle said before it may be stale now
            self.commanded_at = time.time()
        with self.lock:
            self.conn.mav.send(msg)
        if self.tlog is not None:
            self.tlog.write(msg)

    def recv(self, types: list[str] | None = None, timeout: float = 1.0) -> Any:
        return self.conn.recv_match(type=types, blocking=True, timeout=timeout)

    def wait_vehicle(self, timeout: float = 10.0, system_id: int | None = None) -> None:
        """Wait for an autopilot's heartbeat; pick its system id (or the one asked for) and
        its component, the one `from_autopilot` takes from then on. A HEARTBEAT of
        MAV_AUTOPILOT_INVALID or of a component type (NOT_A_VEHICLE) is not an autopilot's:
        some cameras and gimbals have announced an autopilot in theirs."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            msg = self.recv(["HEARTBEAT"], timeout=max(0.05, deadline - time.monotonic()))
            if msg is None or msg.autopilot == M.MAV_AUTOPILOT_INVALID or \
                    msg.type in NOT_A_VEHICLE:
                continue
            if system_id is not None and msg.get_srcSystem() != system_id:
                continue
            self.target_system = msg.get_srcSystem()
            self.target_component = msg.get_srcComponent()
            self.heartbeat_msg, self.heartbeat_at = msg, time.monotonic()
            self.autopilot = autopilot_of(msg)
            self.conn.set_target(self.target_system)
            self.heartbeat()  # announce ourselves now: a udpin link has only now a peer
            return
        raise GcsError(f"no vehicle heartbeat within {timeout:.0f} s")

    def command(self, command: int, *params: float, timeout: float = COMMAND.resend_s,
                retries: int | None = None, ceiling_s: float = COMMAND.ceiling_s,
                silence_s: float = COMMAND.silence_s) -> int:
        """COMMAND_LONG, re-sent each `timeout` without an answer (confirmation
        incremented, at most `retries` times when given); returns the final MAV_RESULT.
        MAV_RESULT_IN_PROGRESS is not final: it stops the re-sends and the wait goes on for
        the final answer (command protocol); each one is progress and restarts the ceiling
        (as MAVSDK does). GcsError when the vehicle falls silent for `silence_s` or no final
        answer comes within `ceiling_s` of asking or of the last IN_PROGRESS
        (`gcs.vehicle_link.patience`).

        The STATUSTEXTs the target sends meanwhile, and after a refusal until
        REFUSAL_TEXT_S passes without one, are kept in `last_texts`: a refusal's reason
        (`describe`)."""
        p = [*params, *([0.0] * (7 - len(params)))]
        self.last_texts = []
        budget = COMMAND.but(resend_s=timeout, ceiling_s=ceiling_s, silence_s=silence_s)
        wait, confirmation, in_progress = Wait(budget), 0, False
        self.command_sends = 1
        self.send(M.MAVLink_command_long_message(self.target_system, self.target_component,
                                                 command, confirmation, *p))
        while not (why := wait.expired()):
            msg = self.recv(["COMMAND_ACK", "STATUSTEXT"], timeout=wait.left())
            wait.note_session(self)  # the autopilot heard (`last_heard`), whatever it sent
            if self.from_autopilot(msg):
                if msg.get_type() == "STATUSTEXT":
                    self.last_texts.append(msg.text)
                elif msg.command == command and self.addressed_to_me(msg):
                    if msg.result == M.MAV_RESULT_IN_PROGRESS:
                        wait.stop_resending()  # working on it: wait for the final answer
                        wait.progressed()  # progress: the ceiling counts from here
                        in_progress = True
                        continue
                    if msg.result != M.MAV_RESULT_ACCEPTED:
                        self._texts_after(REFUSAL_TEXT_S)
                    return int(msg.result)
            if wait.due() and not wait.expired():
                if retries is not None and confirmation >= retries:
                    why = ""  # the tries asked for are spent
                    break
                confirmation += 1
                self.command_sends += 1
                self.send(M.MAVLink_command_long_message(
                    self.target_system, self.target_component, command,
                    min(confirmation, 255), *p))
                wait.sent()
        final = "final " if in_progress else ""
        last = " (the last: MAV_RESULT_IN_PROGRESS)" if in_progress else ""
        raise GcsError(f"no {final}COMMAND_ACK for command {command}{why}{wait.tries_text()}"
                       f"{last}")

    def from_autopilot(self, msg: Any | None) -> TypeGuard[Any]:
        """Whether `msg` came from the target vehicle's autopilot (the component whose
        heartbeat `wait_vehicle` took), not from another component of its system: a
        companion computer's HEARTBEAT says nothing of the autopilot's mode, a gimbal's
        ATTITUDE nothing of the vehicle's (`gcs.vehicle_link.patience.from_target`)."""
        return from_target(msg, self.target_system, self.target_component)

    def addressed_to_me(self, msg: Any) -> bool:
        """Whether an answer (COMMAND_ACK) is this station's: ArduPilot and PX4 address it
        to the command's sender (target_system, target_component; 0 from a sender that
        leaves them unset, MAVLink 1): another station's answer on a shared link is not."""
        mav = self.conn.mav
        return getattr(msg, "target_system", 0) in (0, mav.srcSystem) and \
            getattr(msg, "target_component", 0) in (0, mav.srcComponent)

    def _texts_after(self, quiet_s: float) -> None:
        """Collect the target's STATUSTEXTs until none has come for `quiet_s`."""
        end = time.monotonic() + quiet_s
        while (left := end - time.monotonic()) > 0:
            msg = self.recv(["STATUSTEXT"], timeout=left)
            if self.from_autopilot(msg):
                self.last_texts.append(msg.text)
                end = time.monotonic() + quiet_s

    def texts_since(self, t_monotonic: float) -> list[str]:
        """The target's STATUSTEXTs heard at or after `t_monotonic`, oldest first, whichever
        call read them from the link."""
        return [text for at, system, component, text in list(self.texts)
                if at >= t_monotonic and system == self.target_system and
                (not self.target_component or component == self.target_component)]

    def text_since(self, t_monotonic: float, prefix: str) -> str | None:
        """The first STATUSTEXT of the target starting with `prefix` heard at or after
        `t_monotonic`; None if none."""
        return next((t for t in self.texts_since(t_monotonic) if t.startswith(prefix)), None)

    def describe(self, result: int) -> str:
        """'MAV_RESULT_DENIED: <the vehicle's reason>' for the last command's answer."""
        enum = M.enums["MAV_RESULT"]
        name = enum[result].name if result in enum else f"MAV_RESULT {result}"
        return ": ".join([name, *dict.fromkeys(t for t in self.last_texts if t)])

    def request_streams(self, wanted: dict[str, float]) -> None:
        """Have the vehicle send these messages (name -> Hz) at least this often until the
        session closes (`gcs.autopilot.streams`)."""
        changed = _streams.request(self, wanted)
        self._streams.changed = {**changed.changed, **self._streams.changed}
        self._streams.groups.update(changed.groups)

    def close(self) -> None:
        if self.target_system and (self._streams.changed or self._streams.groups):
            try:
                _streams.restore(self, self._streams)
            except (OSError, GcsError):  # the link has gone: nothing to give back to
                pass
        self._stop.set()
        self._thread.join(timeout=2.0)
        self.conn.close()
        if self.tlog is not None:
            self.tlog.close()
